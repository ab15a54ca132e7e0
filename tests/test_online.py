"""The on-line loop on the simulated lab and on recorded sequences (paper Sec 5)."""

from dataclasses import replace

import numpy as np
import pytest
import yaml

from stablemarks.config import Config
from stablemarks.evaluation import TruthObserver
from stablemarks.geometry import SE2
from stablemarks.io.results import write_run
from stablemarks.metrics import ate_rmse, reobserved_at
from stablemarks.online import run_online
from stablemarks.sim.run import simulate_run
from stablemarks.sim.source import SimulatedSource

from .helpers import assert_psd


def ShortSource(run, n):
    """The first ``n`` frames of a simulated run."""
    return SimulatedSource(run, frames=n)


@pytest.fixture(scope="module")
def lab_short(lab_scenario):
    run = simulate_run(lab_scenario, seed=5)
    truth = TruthObserver()
    return run, truth.result(run_online(ShortSource(run, 11), observers=[truth]))


@pytest.fixture(scope="module")
def lab_short_edges(lab_scenario):
    """The same run with free-edge updates on (``ekf.edge_updates``)."""
    run = simulate_run(lab_scenario, seed=5)
    config = Config().with_overrides({"ekf": {"edge_updates": True}})
    return run, run_online(ShortSource(run, 11), config=config)


@pytest.fixture(scope="module")
def lab_short_walls(lab_scenario):
    """The same run with the fitted walls updating the pose (``ekf.wall_updates``)."""
    run = simulate_run(lab_scenario, seed=5)
    config = Config().with_overrides({"ekf": {"wall_updates": True}, "planes": {"disparity_bias_px": 0.03}})
    return run, run_online(ShortSource(run, 11), config=config)


def test_lab_run_localizes_better_than_dead_reckoning(lab_short):
    run, result = lab_short
    T = result.true_poses
    assert result.ekf.n_landmarks >= 8
    assert result.records[0].new and not result.records[0].observed
    assert ate_rmse(result.poses, T) < ate_rmse(result.dead_reckoning, T)
    # the estimate's uncertainty stays below what odometry alone would give
    assert np.trace(result.covs[-1][:2, :2]) < np.trace(result.cov0[:2, :2])
    for r in result.records:
        assert_psd(r.cov_pose)
    assert_psd(result.ekf.cov)


def test_landmarks_in_view_are_reobserved_at_one_metre(lab_short):
    _, result = lab_short
    seen, missed = reobserved_at(result, 10)
    assert len(seen) >= 6
    assert len(missed) <= 1


def test_new_landmarks_are_wall_landmarks_with_rank_one_covariance(lab_short):
    _, result = lab_short
    for i in result.ekf.landmark_ids:
        lm = result.ekf.landmark(i)
        assert lm.kind == "wall" and lm.plane_id in ("partition", "whiteboard")
        assert np.linalg.matrix_rank(lm.cov2d, tol=1e-14) == 1


def test_dead_reckoning_method_integrates_odometry(lab_scenario):
    run = simulate_run(lab_scenario, seed=2)
    result = run_online(ShortSource(run, 5), method="dead_reckoning")
    np.testing.assert_allclose(result.poses, result.dead_reckoning, atol=1e-12)
    expected = [p.as_array() for p in run.dead_reckoning[:5]]
    np.testing.assert_allclose(result.dead_reckoning, expected, atol=1e-9)
    assert result.ekf.n_landmarks == 0


class BlindSource(SimulatedSource):
    """Frames whose images show nothing: every frame has no observation."""

    def __init__(self, run, n):
        super().__init__(run, frames=n)

    def frame(self, k, pan=None):
        f = super().frame(k, pan)
        return replace(f, left=np.zeros_like(f.left), right=np.zeros_like(f.right))


def test_frames_without_observations_only_predict(lab_scenario):
    run = simulate_run(lab_scenario, seed=3)
    result = run_online(BlindSource(run, 4))
    assert result.ekf.n_landmarks == 0
    assert all(r.n_pairs == 0 and not r.observed for r in result.records)
    np.testing.assert_allclose(result.poses, result.dead_reckoning, atol=1e-12)
    assert np.trace(result.covs[-1]) > np.trace(result.covs[0])


def test_all_segments_baseline_adds_point_landmarks(lab_scenario):
    run = simulate_run(lab_scenario, seed=4)
    result = run_online(ShortSource(run, 2), method="all_segments")
    kinds = {result.ekf.landmark(i).kind for i in result.ekf.landmark_ids}
    assert kinds == {"point"}
    assert_psd(result.ekf.cov)


def test_outputs_and_prior_landmarks_round_trip(lab_short, tmp_path, lab_scenario):
    run, result = lab_short
    paths = write_run(tmp_path, result)
    from stablemarks.io.trajectory import read_tum

    stamps, poses = read_tum(paths["trajectory"])
    np.testing.assert_allclose(poses, result.poses, atol=1e-6)
    _, dr = read_tum(paths["dead_reckoning"])
    np.testing.assert_allclose(dr, result.dead_reckoning, atol=1e-6)
    lines = paths["log"].read_text().splitlines()
    assert len(lines) == len(result.records)
    doc = yaml.safe_load(paths["landmarks"].read_text())
    # the landmark map starts a later run: its landmarks are observed from the first frame on
    again = run_online(ShortSource(run, 2), prior_landmarks=doc)
    assert again.records[0].observed
    prior_ids = {lm["id"] for lm in doc["landmarks"]}
    assert prior_ids <= set(again.ekf.landmark_ids)


def test_unknown_method_is_rejected(lab_scenario):
    run = simulate_run(lab_scenario, seed=1)
    with pytest.raises(ValueError, match="method"):
        run_online(ShortSource(run, 1), method="magic")


def test_se2_between_matches_odometry_increments(lab_scenario):
    """The simulated frames carry odometry poses; their increments are the run's noisy odometry."""
    run = simulate_run(lab_scenario, seed=1)
    frames = list(SimulatedSource(run, frames=4))
    U = SE2.from_array(frames[2].odometry).between(SE2.from_array(frames[3].odometry))
    np.testing.assert_allclose(U.as_array(), run.odometry[3].as_array(), atol=1e-12)
    assert_psd(lab_scenario.robot.odometry.covariance(U))


@pytest.mark.parametrize("extra", ["", "edges", "walls"])
def test_records_replay_the_filter(lab_short, lab_short_edges, lab_short_walls, lab_scenario, extra):
    """The records hold everything the filter used (odometry, priors of new landmarks, measurements, pans, with
    ``ekf.edge_updates`` the free edges found again and with ``ekf.wall_updates`` the fitted walls): replaying
    them through a fresh filter gives the same final state, so a smoother can use them too."""
    from stablemarks.estimation import JointEKF, NewLandmark
    from stablemarks.localizer import apply_wall_measurements

    run, result = {"": lab_short, "edges": lab_short_edges, "walls": lab_short_walls}[extra]
    assert any(r.edge_measurements for r in result.records) is (extra == "edges")
    assert any(r.wall_measurements for r in result.records) is (extra == "walls")

    ekf = JointEKF(Config().camera(lab_scenario.camera), SimulatedSource(run).initial_pose, result.cov0)
    for rec in result.records:
        if rec.odometry is not None:
            ekf.predict(rec.odometry, rec.cov_odometry)
        for i in rec.dropped:
            ekf.remove_landmark(i)
        if rec.inflation != 1.0:
            ekf.inflate_pose(rec.inflation, position_only=True)
        if rec.measurements:
            ekf.update([(i, (ul, ur)) for i, ul, ur in rec.measurements], rec.pan, frame=rec.index,
                       iterations=Config().ekf.iterations)
        for ids, values, cov in rec.landmark_priors:
            new = []
            for i, s in zip(ids, values, strict=True):
                lm = result.ekf.landmark(i)
                new.append(NewLandmark.wall(result.world_map[lm.plane_id], s, lm.edge, lm.z_low, lm.z_high))
            tie = [(G, X) for i, G, X in rec.landmark_couplings if list(i) == list(ids)]
            if tie:  # entered tied to the pose (ekf.tie_blind_entries)
                G = np.asarray(tie[0][0])
                ekf.add_landmarks(new, np.asarray(cov) + G @ ekf.cov_pose @ G.T, cov_pose_new=ekf.cov_pose @ G.T,
                                  ids=ids)
            else:
                ekf.add_landmarks(new, cov, ids=ids)
        if rec.edge_measurements:  # free edges found again (ekf.edge_updates), after the landmarks entered
            wm = result.world_map
            ekf.update_known_points([wm[p].edge(e) for p, e, *_ in rec.edge_measurements],
                                    [(ul, ur) for _, _, ul, ur, _ in rec.edge_measurements],
                                    np.array([c for *_, c in rec.edge_measurements]), rec.pan,
                                    cov_points=np.stack([wm.edge_cov(p, e) for p, e, *_ in rec.edge_measurements]))
        apply_wall_measurements(ekf, rec.wall_measurements)  # the fitted walls (ekf.wall_updates), after the edges
    assert sum(len(r.measurements) for r in result.records) > 20
    np.testing.assert_allclose(ekf.pose, result.ekf.pose, atol=1e-12)
    np.testing.assert_allclose(ekf.cov_pose, result.ekf.cov_pose, atol=1e-15)
    np.testing.assert_allclose(ekf.cov, result.ekf.cov, atol=1e-15)


def _untimed(log_path) -> list[dict]:
    import json

    lines = [json.loads(line) for line in log_path.read_text().splitlines()]
    for r in lines:
        assert set(r.pop("timings")) >= {"segments", "total"}
    return lines


def test_log_is_streamed_while_the_loop_keeps_only_poses(lab_scenario, tmp_path):
    """``LogWriter`` writes ``log.jsonl`` frame by frame, line for line what ``write_run`` writes from the whole
    records; with ``keep="poses"`` the loop holds only what the end-of-run outputs read, with ``"nothing"``
    nothing (and still counts the frames)."""
    from stablemarks.io.results import LogWriter
    from stablemarks.online import PoseRecord

    run = simulate_run(lab_scenario, seed=6)
    lines_seen = []

    def after_log(frame, est, localizer):  # the line is on disk before the next observer runs
        lines_seen.append(len((tmp_path / "streamed" / "log.jsonl").read_text().splitlines()))

    with LogWriter(tmp_path / "streamed" / "log.jsonl") as log:
        full = run_online(ShortSource(run, 4), observers=[log, after_log])
    assert lines_seen == [1, 2, 3, 4] and log.frames == 4
    paths = write_run(tmp_path / "whole", full)
    assert (tmp_path / "streamed" / "log.jsonl").read_text() == paths["log"].read_text()

    with LogWriter(tmp_path / "slim" / "log.jsonl") as log:
        slim = run_online(ShortSource(run, 4), observers=[log], keep="poses")
    assert all(isinstance(r, PoseRecord) for r in slim.records) and slim.n_frames == full.n_frames == 4
    assert not hasattr(slim.records[0], "measurements")
    for name in ("stamps", "poses", "covs", "dead_reckoning", "true_poses"):
        np.testing.assert_array_equal(getattr(slim, name), getattr(full, name), err_msg=name)
    assert [r.pan for r in slim.records] == [r.pan for r in full.records]
    assert [r.n_landmarks for r in slim.records] == [r.n_landmarks for r in full.records]
    written = write_run(tmp_path / "slim", slim, log=log.path)
    assert written["log"] == log.path
    for name in ("trajectory", "dead_reckoning", "groundtruth", "landmarks"):
        assert written[name].read_text() == paths[name].read_text(), name
    assert _untimed(tmp_path / "slim" / "log.jsonl") == _untimed(paths["log"])  # another run: other wall times
    with pytest.raises(ValueError, match="keep='poses'"):
        write_run(tmp_path / "nolog", slim)
    assert not (tmp_path / "nolog").exists()

    none = run_online(ShortSource(run, 4), keep="nothing")
    assert none.records == [] and none.n_frames == 4
    np.testing.assert_array_equal(none.ekf.state, full.ekf.state)
    with pytest.raises(ValueError, match="keep"):
        run_online(ShortSource(run, 1), keep="some")


def test_an_interrupted_run_keeps_its_streamed_log(lab_scenario, tmp_path):
    """The log of the frames done is on disk, whole lines, when the loop stops with an error."""
    import json

    from stablemarks.io.results import LogWriter

    class Broken(SimulatedSource):
        def frame(self, k, pan=None):
            if k == 2:
                raise OSError("the recording ends here")
            return super().frame(k, pan)

    run = simulate_run(lab_scenario, seed=6)
    with pytest.raises(OSError), LogWriter(tmp_path / "log.jsonl") as log:
        run_online(Broken(run, frames=4), observers=[log], keep="poses")
    lines = (tmp_path / "log.jsonl").read_text().splitlines()
    assert [json.loads(line)["index"] for line in lines] == [0, 1]


class Unrendered:
    """A renderer that fails when asked for images; the geometric truth is the scenario renderer's."""

    def __init__(self, scenario):
        from stablemarks.sim.render import renderer_for

        self.renderer = renderer_for(scenario)

    def render(self, X, pan, rng):
        raise AssertionError("a frame was rendered")

    def truth(self, X, pan):
        return self.renderer.truth(X, pan)


class AlwaysRendered(SimulatedSource):
    """A simulated source that renders every frame whatever the method (as before methods without vision
    skipped it); ``renders`` counts its renderings."""

    rendering = property(lambda self: True, lambda self, value: None)

    def __init__(self, run, n):
        super().__init__(run, frames=n)
        self.renders = 0

    def _shot(self, k, X, pan):
        self.renders += 1
        return super()._shot(k, X, pan)


def test_dead_reckoning_renders_nothing_and_runs_as_with_the_images(lab_scenario):
    """A method that reads no images gets frames without them (nothing rendered) and the same run, figure for
    figure, as from the rendered frames: the frames' random streams are their own, the truth is geometry."""
    from stablemarks.sim.render import renderer_for

    run = simulate_run(lab_scenario, seed=6)
    results, truths = [], []
    blind = SimulatedSource(run, renderer=Unrendered(lab_scenario), frames=10)
    seen = AlwaysRendered(run, 10)
    for source in (blind, seen):
        truth = TruthObserver()
        results.append(truth.result(run_online(source, method="dead_reckoning", observers=[truth])))
        truths.append(truth)
    assert seen.renders == 10 and not blind.rendering
    without, rendered = results
    assert without.n_frames == rendered.n_frames == 10
    for name in ("poses", "covs", "dead_reckoning", "true_poses"):
        np.testing.assert_allclose(getattr(without, name), getattr(rendered, name), rtol=0, atol=1e-12)
    for a, b in zip(without.records, rendered.records, strict=True):
        assert (a.pan, a.pan_command, a.n_pairs, a.new, a.observed) == (b.pan, b.pan_command, b.n_pairs, b.new,
                                                                        b.observed)
    assert without.visible_truth == rendered.visible_truth and any(without.visible_truth)
    assert (without.truth_of, without.rejected_truth) == (rendered.truth_of, rendered.rejected_truth) == ({}, {})
    # the true edges agree but for what only the images decide: a boundary's polarity
    assert truths[0].edges.keys() == truths[1].edges.keys()
    for eid, e in truths[0].edges.items():
        assert _geometric(e) == _geometric(truths[1].edges[eid])
    full = renderer_for(lab_scenario).render(run.poses[3].as_array(), run.pans[3], run.frame_rng(3)).truth
    geometric = renderer_for(lab_scenario).truth(run.poses[3].as_array(), run.pans[3])
    assert [_geometric(e) for e in geometric.edges] == [_geometric(e) for e in full.edges]
    assert any(e.visible_l and e.visible_r for e in full.edges)
    assert (geometric.pose, geometric.pan) == (full.pose, full.pan)


def _geometric(edge):
    """A true edge without what the images decide (a boundary's polarity)."""
    return replace(edge, polarity=0) if edge.boundary else edge


def test_a_method_with_vision_still_gets_rendered_frames(lab_scenario):
    source = SimulatedSource(simulate_run(lab_scenario, seed=6), frames=1)
    source.rendering = False  # left over from a run without vision: the next run sets it
    frames = []
    run_online(source, observers=[lambda frame, est, loc: frames.append(frame)])
    assert source.rendering and frames[0].left.shape == frames[0].right.shape == (lab_scenario.camera.height,
                                                                                  lab_scenario.camera.width)
