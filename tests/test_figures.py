"""Smoke tests of the figures on small synthetic inputs: each writes a non-empty PNG, its legends carry the
labels a reader needs, and labels meant not to collide do not."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from matplotlib.colors import to_rgb

from stablemarks.maps import Map, ReferencePlane
from stablemarks.viz import frames, report, scene, trajectory, walls

H, W = 120, 160
PARTITION = ReferencePlane("partition", (0.0, 4.0), (1.2, 4.0), name="partition", free_edges=("p1",))
BOARD = ReferencePlane("board", (-0.5, 6.0), (-2.3, 6.0), name="white board", free_edges=("p1", "p2"))
BACK = ReferencePlane("back", (-4.0, 8.5), (4.0, 8.5), name="back", reference=False)
WORLD = Map((PARTITION, BOARD, BACK))


class Pairs:
    """The fields of :class:`SegmentPairs` the figures read."""

    def __init__(self, u, top, bottom):
        self.u_left, self.v_top, self.v_bottom = (np.asarray(a, float) for a in (u, top, bottom))

    def __len__(self):
        return len(self.u_left)


def candidate(plane, index, s, selected, sigma=0.03, u=60.0, edge="p1"):
    P = plane.point_at(s, edge)
    d = plane.direction if edge == "p1" else -plane.direction
    return SimpleNamespace(plane_id=plane.id, plane_label=plane.label, index=index, edge=edge, s=s, sigma_s=sigma,
                           P=P, cov=sigma**2 * np.outer(d, d), P_observed=P + [0.0, 0.004],
                           cov_observed=np.diag([sigma**2, 0.01**2]), selected=selected,
                           reason="" if selected else "near boundary", u_left=u, v_top=25.0, v_bottom=80.0)


@pytest.fixture()
def frame_result():
    valid = np.zeros((H, W), bool)
    valid[20:100, 10:150] = True
    region = np.zeros((H, W), bool)
    region[30:90, 40:110] = True
    fit = SimpleNamespace(region=region, plane=PARTITION)
    boundary = SimpleNamespace(u=np.array([42.0, 30.0]), sigma_u=np.array([1.6, 1.6]), edge="p1")
    cands = [candidate(PARTITION, 1, 0.03, False, u=45.0), candidate(PARTITION, 2, 0.031, False, u=46.0),
             candidate(PARTITION, 3, 0.20, True, u=70.0), candidate(PARTITION, 4, 0.45, True, u=90.0),
             candidate(BOARD, 1, 0.05, False, u=120.0), candidate(BOARD, 2, 0.5, True, u=130.0)]
    front = SimpleNamespace(kept_pairs=Pairs([45, 70, 90, 140], [25, 30, 25, 20], [80, 90, 70, 95]),
                            disparity=SimpleNamespace(valid=valid))
    return SimpleNamespace(front=front, fits=[fit], planes=[SimpleNamespace(fit=fit, boundaries=[boundary])],
                           candidates=cands, X=np.array([0.6, 0.0, np.pi / 2]))


def legend_texts(fig) -> list[str]:
    out = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    for ax in fig.axes:
        if ax.get_legend() is not None:
            out += [t.get_text() for t in ax.get_legend().get_texts()]
    return out


def written(path: Path) -> np.ndarray:
    img = cv2.imread(str(path))
    assert img is not None and img.size > 0 and img.std() > 5, path
    return img


def boxes_overlap(texts, renderer) -> list[tuple[str, str]]:
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in texts if t.get_text()]
    return [(a, b) for i, (a, ba) in enumerate(boxes) for b, bb in boxes[i + 1:] if ba.overlaps(bb)]


def test_figure6_legend_colours_and_sigma_zooms(tmp_path, frame_result):
    left = np.full((H, W), 100, np.uint8)
    fig = frames.make_figure6(left, frame_result)
    labels = legend_texts(fig)
    for expected in ("SAD match (valid disparity)", "no SAD match", "planar region: partition",
                     "segment pair kept by the disparity check", "feature selected as landmark", "feature rejected"):
        assert expected in labels, labels
    assert any(label.startswith("plane's free edge found, ±σ") for label in labels)
    handles = {t.get_text(): h for leg in fig.legends for t, h in zip(leg.get_texts(), leg.legend_handles, strict=True)}
    sad = np.asarray(handles["SAD match (valid disparity)"].get_facecolor())[:3]
    segment = np.array(to_rgb(handles["segment pair kept by the disparity check"].get_color()))
    assert np.abs(sad - segment).max() > 0.3  # SAD matches and segments in distinct colours
    assert len(fig.axes) == 2  # the image and one zoom on the free edge
    assert "± 1.6 px" in fig.axes[1].get_title()
    written(frames.figure6(tmp_path / "fig6.png", left, frame_result))


def test_figure6_front_legend(tmp_path, frame_result):
    left = np.full((H, W), 100, np.uint8)
    fig = frames.make_figure6_front(left, frame_result.front)
    assert {"SAD match (valid disparity)", "no SAD match", "segment pair kept by the disparity check"} <= set(
        legend_texts(fig))
    written(frames.figure6_front(tmp_path / "fig6_front.png", left, frame_result.front))


def test_figure7_zoom_per_plane(tmp_path, frame_result):
    truth = {"points": [[0.03, 4.0], [0.2, 4.0]]}
    fig = frames.make_figure7(frame_result, WORLD, None, truth)
    labels = legend_texts(fig)
    assert "selected feature: ±3σ along the wall" in labels and "rejected feature: ±3σ along the wall" in labels
    assert "true feature" in labels and "wall (occluder only)" in labels
    zooms = [ax for ax in fig.axes if ": zoom" in ax.get_title()]
    assert len(zooms) == 2 and all("equal axes" in ax.get_title() for ax in zooms)
    written(frames.figure7(tmp_path / "fig7.png", frame_result, WORLD, None, truth))


def test_zoom_figure7_numbers_as_table1_without_overlaps(tmp_path, frame_result):
    c = frame_result.candidates
    row = lambda plane, index: SimpleNamespace(plane=plane, index=index)  # noqa: E731
    # the paper's rows 1–3 of the partition matched; c[1] is a candidate the paper does not list
    matches = [(row("partition", 1), c[0]), (row("partition", 2), c[2]), (row("partition", 3), c[3]),
               (row("whiteboard", 1), c[4]), (row("whiteboard", 2), None)]
    fig = frames.make_zoom_figure7(frame_result, ["board", "partition"], matches)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        assert not boxes_overlap(ax.texts, renderer)
    numbers = sorted(t.get_text() for ax in fig.axes for t in ax.texts)
    assert numbers == sorted(["1", "+", "2", "3", "1", "+"])  # c[5] (board) is not in the paper's rows either
    assert any("not in the paper's Table 1" in label for label in legend_texts(fig))
    written(frames.zoom_figure7(tmp_path / "fig7_along.png", frame_result, ["board", "partition"], matches))
    ours = frames.make_zoom_figure7(frame_result, ["partition"])  # without matches: our own index
    assert sorted(t.get_text() for ax in ours.axes for t in ax.texts) == ["1", "2", "3", "4"]


def test_map_labels_do_not_collide(tmp_path):
    from stablemarks.sim.run import simulate_run
    from stablemarks.sim.scenario import load_scenario

    scenario = load_scenario("lab")
    run = simulate_run(scenario, None)
    fig = scene.scene_figure(scenario, run)
    fig.canvas.draw()
    ax = fig.axes[0]
    assert not boxes_overlap(ax.texts, fig.canvas.get_renderer())
    assert {"partition p1", "white board p1"} <= {t.get_text() for t in ax.texts}
    assert any("free edge" in label for label in legend_texts(fig))
    written(scene.save_scene_figure(tmp_path / "map.png", scenario, run))


def fake_run():
    n = 11
    y = np.linspace(0.0, 2.0, n)
    poses = np.column_stack([0.01 * y, y, np.full(n, np.pi / 2)])
    covs = np.array([np.diag([0.05**2 * (1 + k), 0.02**2, 1e-4]) for k in range(n)])
    landmarks = {0: SimpleNamespace(position=np.array([0.3, 4.0]), cov2d=np.diag([0.03**2, 0.0]), plane_id="partition"),
                 1: SimpleNamespace(position=np.array([1.0, 3.0]), cov2d=np.diag([0.02**2, 0.01**2]), plane_id=None)}
    ekf = SimpleNamespace(landmark_ids=list(landmarks), landmark=lambda i: landmarks[i])
    return SimpleNamespace(poses=poses, covs=covs, dead_reckoning=poses + [0.02, 0.0, 0.0],
                           true_poses=poses * [0, 1, 1], stamps=np.arange(n) * 0.5, ekf=ekf, world_map=WORLD,
                           name="synthetic", method="stablemarks", records=[])


def test_figure10_legends_and_equal_axes(tmp_path):
    fig = trajectory.make_figure10(fake_run())
    main_ax, zoom_ax = fig.axes
    main = [t.get_text() for t in main_ax.get_legend().get_texts()]
    assert {"wall: reference plane", "wall in the map only as occluder", "free edge", "true path",
            "dead reckoning"} <= set(main)
    assert any(label.startswith("landmark ±2σ") for label in main)
    assert zoom_ax.get_legend() is not None  # the zoom has its own legend
    zoom = [t.get_text() for t in zoom_ax.get_legend().get_texts()]
    assert "true path" in zoom and any("2σ position ellipse" in label for label in zoom)
    assert main_ax.get_aspect() == 1.0 and zoom_ax.get_aspect() == 1.0  # ellipses keep their shape
    written(trajectory.figure10(tmp_path / "fig10.png", fake_run()))


def test_nees_figure_integer_frame_ticks(tmp_path):
    summary = {"lab": {m: {"nees_pose_time": list(np.linspace(2.0, 4.0, 7) * (1 + k)), "nees_pose_bounds": [2.4, 3.7],
                           "trials": 2} for k, m in enumerate(["stablemarks", "dead_reckoning"])}}
    fig = report.make_nees_figure(summary)
    fig.canvas.draw()
    ticks = [t for t in fig.axes[0].get_xticks() if 0 <= t <= 6]
    assert ticks and all(float(t).is_integer() for t in ticks)
    assert {"stablemarks", "dead_reckoning", "95 % bounds"} <= set(legend_texts(fig))
    written(report.nees_figure(tmp_path / "nees.png", summary))


def test_walls_figure_zoom_per_free_edge(tmp_path):
    from stablemarks.io.mapfiles import OccupancyMap, walls_from_occupancy

    grid = np.zeros((40, 80), np.int8)
    grid[20, 10:70] = 100
    occupancy = OccupancyMap(grid, 0.05, np.zeros(3), "synthetic")
    extracted = walls_from_occupancy(grid, 0.05, np.zeros(3))
    fig = walls.walls_figure(occupancy, extracted)
    n_free = sum(len(p.free_edges) for p in extracted)
    assert n_free == 4 and len(fig.axes) == 1 + n_free  # the map and one zoom per free edge
    labels = legend_texts(fig)
    assert "free edge (Zn: its zoom below)" in labels and "tick: the side it is seen from (visible_from)" in labels
    img = written(walls.save_walls_figure(tmp_path / "walls.png", occupancy, extracted))
    assert img.shape[1] >= 1000
