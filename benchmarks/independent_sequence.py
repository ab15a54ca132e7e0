"""A whole recorded sequence rendered by a renderer that is not the project's, run through the on-line localizer.

Why: the filter must have an honest covariance on scenes and images it was never tuned on. Every trajectory-level
evaluation so far renders with the project's own simulator (:mod:`stablemarks.sim`), whose optics, procedural
textures and painted vertical features the method was tuned on. Here the images of a whole run come from pybullet's
TinyRenderer (headless, ``p.DIRECT``; :mod:`tests.independent_render`, whose pinhole convention its test measures)
with photographs from ``skimage.data`` as textures, so the localizer sees a scene made by code that knows nothing
of it, at the same true poses, with the same map, calibration, pans and noisy odometry.

Per scenario:

1. ``stablemarks simulate SCENARIO --out OUT/SCENARIO/sim --frames N --seed S`` writes the run as a sequence folder
   (the project's own images, kept for comparison).
2. The folder is copied to ``OUT/SCENARIO/pybullet`` and every left/right PNG replaced by a pybullet rendering of
   the same scenario at the frame's true camera pose (``groundtruth.tum`` + the ``pan`` column of ``frames.csv``):
   each wall a textured surface over its ``p1 → p2`` and ``z`` range (a flattened photograph, gravel, brick or
   grass, tiled as its base, with photographs pasted on it as posters whose sides are the vertical lines the
   method uses; the simulator's painted features are not reproduced), faced towards the sides it is visible from
   (``visible_from``); boxes as four textured sides and a top; poles as grey cylinders; a textured floor and
   ceiling; grey ``background`` where nothing is; 3 × 3 supersampling, Gaussian noise of 2 grey levels; the
   project's intrinsics exactly; 8-bit grayscale PNGs of the same size, as ``simulate`` writes them.
   ``groundtruth.json`` is left in place: its poses and odometry still hold, its image edges (the painted
   features) do not.
3. ``stablemarks run OUT/SCENARIO/pybullet --out OUT/SCENARIO/run_pybullet --no-figures`` runs the localizer;
   ``log.jsonl`` gives per-frame ``pose``, ``cov_pose``, ``true_pose``, ``dead_reckoning``, ``nis``, ``warnings``.

Printed per scenario: frames, ATE [mm] of the filter and of dead reckoning and their ratio, the mean pose NEES
(3 dof, heading error wrapped) and the share of frames inside the 95 % χ² bounds of one run ([0.216, 9.35]) and
above them (frame 0, the prior at the true start, left out), the mean NIS (2 dof per observation), the most
landmarks held and the observations per frame, the seconds spent rendering and running, the warnings in the log,
and a geometry check (``geom``): the share of pixels (whole-pixel labels of pybullet, left images, worst frame)
where pybullet and the project's ray caster (:meth:`stablemarks.sim.world.World.zbuffer` at the pixel centre) see
different objects — walls' ends are where it would show. ``--with-sim`` also runs the project-rendered folder (same
run, the project's images) for a row to compare with; ``--calibrate-noise`` also runs ``stablemarks calibrate-noise`` on
the pybullet folder and saves what it prints. ``OUT/SCENARIO/compare/`` holds side-by-side PNGs (project's render
| pybullet's) of a few frames, ``OUT/SCENARIO/frames_pybullet.csv`` (and ``frames_project.csv``) the per-frame
NEES, errors, σ, observations and warnings, and ``OUT/SCENARIO/run_*.txt`` what ``stablemarks run`` printed.

    python benchmarks/independent_sequence.py office lab hall --frames 60 --seed 0 --out /tmp/indep --with-sim
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import shutil
import subprocess
import sys
import time
import zlib
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.independent_render import (  # noqa: E402
    Pole,
    Scene,
    SceneRenderer,
    Surface,
    fit_texture,
    gray_photo,
)

from stablemarks.commands._common import preset_arg  # noqa: E402
from stablemarks.io.sequence import load_sequence  # noqa: E402
from stablemarks.metrics import ate_rmse, pose_nees  # noqa: E402
from stablemarks.sim.scenario import Scenario, count_frames, load_scenario  # noqa: E402
from stablemarks.sim.world import BACKGROUND, CEILING, FLOOR, World  # noqa: E402

BOUNDS_1RUN = (0.216, 9.35)
"""95 % χ² bounds of one 3-dof pose NEES: χ²⁻¹(0.025; 3), χ²⁻¹(0.975; 3)."""
TEXEL = 0.004
"""Texel of wall textures [m] (coarser on walls longer than :data:`MAX_TEXELS` texels)."""
MAX_TEXELS = 4096
BASE_PHOTOS = ("gravel", "brick", "grass")
"""Photographs tiled as the base of walls and boxes (flattened and set to the scenario's grey level)."""
POSTER_PHOTOS = ("camera", "coffee", "astronaut", "chelsea", "rocket", "text", "moon", "page", "clock", "coins",
                 "hubble_deep_field", "immunohistochemistry")
"""Photographs pasted on walls as posters: their sides are the vertical lines the method uses."""
NOISE_SIGMA = 2.0
SUPERSAMPLE = 3
VENV_BIN = Path(sys.executable).parent


# ------------------------------------------------------------------ the scene from a scenario
def _crop_to(img: np.ndarray, aspect: float) -> np.ndarray:
    """The centre crop of ``img`` with width / height ``aspect``."""
    h, w = img.shape
    if w / h > aspect:
        cw = max(1, int(round(h * aspect)))
        return img[:, (w - cw) // 2:(w - cw) // 2 + cw]
    ch = max(1, int(round(w / aspect)))
    return img[(h - ch) // 2:(h - ch) // 2 + ch, :]


def base_texture(shape: tuple[int, int], texel: float, photo: str, level: float, contrast: float = 0.35,
                 tile_m: float = 1.2) -> np.ndarray:
    """(H, W) float: ``photo`` tiled every ``tile_m`` [m], flattened to ``contrast`` of its spread about
    ``level`` [grey]."""
    n = max(8, int(round(tile_m / texel)))
    tile = fit_texture(gray_photo(photo), n, n).astype(float)
    tile = level + contrast * (tile - tile.mean())
    H, W = shape
    return np.tile(tile, (H // n + 1, W // n + 1))[:H, :W]


def wall_posters(key: str, length: float, z: tuple[float, float]) -> list[tuple[str, float, float, float, float]]:
    """Posters ``(photo, s0, s1, z0, z1)`` [m] on a wall of ``length`` and height range ``z`` (``s`` from ``p1``,
    ``z`` above the floor), drawn from a generator seeded by ``key``: widths 0.25–0.9 m, gaps 0.2–1.2 m, kept
    8 cm inside the wall's ends and 10 cm inside its top and bottom; no photograph twice on one wall."""
    rng = np.random.default_rng(zlib.crc32(key.encode()))
    photos = list(rng.permutation(POSTER_PHOTOS))
    lo, hi = z[0] + 0.1, min(z[1] - 0.1, 2.3)
    if hi - lo < 0.2:
        return []
    out = []
    s = 0.08 + rng.uniform(0.0, 0.6)
    while photos:
        width = rng.uniform(0.25, 0.9)
        if s + width > length - 0.08:
            break
        height = rng.uniform(0.25, min(0.9, hi - lo))
        z0 = rng.uniform(lo, hi - height)
        out.append((str(photos.pop()), s, s + width, z0, z0 + height))
        s += width + rng.uniform(0.2, 1.2)
    return out


def board(length: float, height: float, level: float, photo: str, posters=(), z0: float = 0.0
          ) -> tuple[np.ndarray, float]:
    """A wall's texture (rows top to bottom, columns from ``p1``) and its texel [m]: the base photograph with
    ``posters`` ``(photo, s0, s1, z0, z1)`` pasted on it (``z`` above the floor; the wall's bottom is ``z0``)."""
    texel = max(TEXEL, length / MAX_TEXELS, height / MAX_TEXELS)
    W, H = max(2, int(round(length / texel))), max(2, int(round(height / texel)))
    img = base_texture((H, W), texel, photo, level)
    for name, s0, s1, pz0, pz1 in posters:
        c0, c1 = int(round(s0 / texel)), int(round(s1 / texel))
        r0, r1 = H - int(round((pz1 - z0) / texel)), H - int(round((pz0 - z0) / texel))
        photo_img = _crop_to(gray_photo(name), (s1 - s0) / (pz1 - pz0))
        img[r0:r1, c0:c1] = fit_texture(photo_img, c1 - c0, r1 - r0)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), texel


def _faces(name: str, p1, p2, z: tuple[float, float], texture: np.ndarray, sides: str) -> list[Surface]:
    """A vertical rectangle over ``p1 → p2`` and ``z`` with ``texture`` (columns from ``p1``), as the faces
    seen from ``sides`` (``left``/``right`` of ``p1 → p2`` or ``both``); the same point of the wall shows the same
    texel from either side."""
    p1, p2 = np.asarray(p1, float), np.asarray(p2, float)
    L, h = float(np.hypot(*(p2 - p1))), z[1] - z[0]
    out = []
    if sides in ("right", "both"):  # along p1→p2, up: along × up points to the right of p1 → p2
        out.append(Surface(f"{name}|right", (p1[0], p1[1], z[0]), (*(p2 - p1), 0.0), (0.0, 0.0, h), texture, (L, h)))
    if sides in ("left", "both"):
        out.append(Surface(f"{name}|left", (p2[0], p2[1], z[0]), (*(p1 - p2), 0.0), (0.0, 0.0, h),
                           np.ascontiguousarray(texture[:, ::-1]), (L, h)))
    return out


def scenario_scene(sc: Scenario, bases: tuple[str, ...] = BASE_PHOTOS) -> tuple[Scene, dict[str, list]]:
    """The pybullet scene of scenario ``sc`` and the posters of each wall (``wall id → posters``); wall ``i`` and
    box ``i`` have the base photograph ``bases[i % len(bases)]`` and ``bases[(i + 1) % len(bases)]``."""
    surfaces: list[Surface] = []
    posters: dict[str, list] = {}
    for i, w in enumerate(sc.walls):
        L = w.plane.length
        posters[w.id] = wall_posters(f"{sc.name}:{w.id}", L, w.z)
        tex, _ = board(L, w.z[1] - w.z[0], w.texture.base, bases[i % len(bases)], posters[w.id], w.z[0])
        surfaces += _faces(w.id, w.p1, w.p2, w.z, tex, w.visible_from)
    for i, b in enumerate(sc.boxes):
        c = b.corners()  # counter-clockwise: outward is to the right of each side
        photo = bases[(i + 1) % len(bases)]
        for j in range(4):
            a, e = c[j], c[(j + 1) % 4]
            L = float(np.hypot(*(e - a)))
            tex, _ = board(L, b.height, b.texture.base, photo)
            surfaces += _faces(f"{b.id}#{j}", a, e, (0.0, b.height), tex, "right")
        sx, sy = float(np.hypot(*(c[1] - c[0]))), float(np.hypot(*(c[3] - c[0])))
        tex, _ = board(sx, sy, b.texture.base, photo)
        surfaces.append(Surface(f"{b.id}|top", (c[0][0], c[0][1], b.height), (*(c[1] - c[0]), 0.0),
                                (*(c[3] - c[0]), 0.0), tex, (sx, sy)))
    pts = np.array([p for w in sc.walls for p in (w.p1, w.p2)])
    x0, y0 = np.floor(pts.min(axis=0)) - 2.0
    x1, y1 = np.ceil(pts.max(axis=0)) + 2.0
    room = sc.room
    floor = base_texture((400, 400), 1.0 / 400, "grass", room.floor.base, contrast=0.6, tile_m=1.0)
    surfaces.append(Surface("floor", (x0, y0, 0.0), (x1 - x0, 0.0, 0.0), (0.0, y1 - y0, 0.0),
                            np.clip(floor, 0, 255).astype(np.uint8), (1.0, 1.0)))
    if room.ceiling_height is not None:  # facing down: along +y, up +x
        ceil = base_texture((400, 400), 1.0 / 400, "gravel", room.ceiling.base, contrast=0.15, tile_m=1.0)
        surfaces.append(Surface("ceiling", (x0, y0, room.ceiling_height), (0.0, y1 - y0, 0.0), (x1 - x0, 0.0, 0.0),
                                np.clip(ceil, 0, 255).astype(np.uint8), (1.0, 1.0)))
    poles = tuple(Pole(p.id, p.center[0], p.center[1], p.radius, p.height, p.texture.base / 255.0) for p in sc.poles)
    return Scene(tuple(surfaces), poles), posters


# ------------------------------------------------------------------ geometry check against the project's caster
def project_labels(world: World, camera, X) -> np.ndarray:
    """(H, W) object ids (``floor``, ``ceiling``, ``background`` or a wall/box/pole id) the project's ray caster
    sees at the left image's pixel centres."""
    origin = camera.optical_centres(X)[0]
    psi = camera.camera_pose(X).theta
    fwd, right = np.array([math.cos(psi), math.sin(psi)]), np.array([math.sin(psi), -math.cos(psi)])
    dirs = fwd + ((np.arange(camera.width) - camera.cu) / camera.f)[:, None] * right
    _, pid = world.zbuffer(world.cast(origin, dirs), np.arange(camera.height, dtype=float), camera.mount_height,
                           camera.f, camera.cv)
    names = {FLOOR: "floor", CEILING: "ceiling", BACKGROUND: "background"}
    out = np.empty(pid.shape, dtype=object)
    for k in np.unique(pid):
        out[pid == k] = names[int(k)] if k < 0 else world.objects[world.primitive_owner(int(k))].id
    return out


def label_ids(pair) -> np.ndarray:
    """(H, W) object ids of pybullet's whole-pixel labels of the left image (``None`` where mixed or empty)."""
    ids = np.array([n.split("|")[0].split("#")[0] for n in pair.names] + [None], dtype=object)
    return ids[np.where(pair.labels_left >= 0, pair.labels_left, -1)]


# ------------------------------------------------------------------ one scenario
@dataclass
class Row:
    scenario: str
    images: str
    frames: int
    ate_mm: float
    dr_ate_mm: float
    nees_mean: float
    inside: float
    above: float
    nis_mean: float
    landmarks: int
    obs_per_frame: float
    render_s: float
    run_s: float
    mismatch: float
    warnings: int
    outliers: tuple = ()

    @property
    def ratio(self) -> float:
        return self.ate_mm / self.dr_ate_mm


def stablemarks(*args: str, log: Path | None = None) -> str:
    """Run the ``stablemarks`` command; its output (also written to ``log``)."""
    res = subprocess.run([str(VENV_BIN / "stablemarks"), *args], capture_output=True, text=True)
    text = res.stdout + res.stderr
    if log is not None:
        log.write_text(text)
    if res.returncode != 0:
        raise RuntimeError(f"stablemarks {' '.join(args)} failed ({res.returncode}):\n{text}")
    return text


def render_sequence(seq_dir: Path, sc: Scenario, seed: int, compare_dir: Path | None = None,
                    compare_frames=(), bases: tuple[str, ...] = BASE_PHOTOS) -> tuple[float, float]:
    """Replace every PNG of ``seq_dir`` by pybullet's rendering; returns (seconds, worst per-frame share of
    pixels where pybullet and the project's caster see different objects)."""
    seq = load_sequence(seq_dir)
    if seq.camera.width != sc.camera.width or seq.camera.f != sc.camera.f or seq.camera.cu != sc.camera.cu:
        raise RuntimeError(f"calibration of {seq_dir} differs from scenario {sc.name}'s camera")
    scene, _ = scenario_scene(sc, bases)
    world = World.from_scenario(sc)
    light = np.array([-1.0, -2.0, 3.0])
    worst = 0.0
    start = time.perf_counter()
    with SceneRenderer(scene) as r:
        for k in range(len(seq)):
            camera, X = seq.camera_at(k), seq.groundtruth[k]
            rng = np.random.default_rng([seed, 7, k])
            pair = r.render(camera, X, supersample=SUPERSAMPLE, noise_sigma=NOISE_SIGMA, rng=rng,
                            background=sc.room.background, light_direction=light)
            old = cv2.imread(str(seq.left_paths[k]), cv2.IMREAD_UNCHANGED)
            if old.shape != pair.left.shape or old.dtype != pair.left.dtype:
                raise RuntimeError(f"{seq.left_paths[k]}: {old.shape} {old.dtype} against {pair.left.shape}")
            ours, theirs = label_ids(pair), project_labels(world, camera, X)
            known = ours != None  # noqa: E711 (object array)
            worst = max(worst, float(np.mean(ours[known] != theirs[known])))
            if compare_dir is not None and k in compare_frames:
                compare_dir.mkdir(parents=True, exist_ok=True)
                gap = np.full((old.shape[0], 8), 255, np.uint8)
                cv2.imwrite(str(compare_dir / f"{k:06d}.png"), np.hstack([old, gap, pair.left]))
            cv2.imwrite(str(seq.left_paths[k]), pair.left)
            cv2.imwrite(str(seq.right_paths[k]), pair.right)
    return time.perf_counter() - start, worst


def read_log(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def evaluate(run_dir: Path, seq_dir: Path) -> dict:
    """Per-frame and summary figures of a run of ``stablemarks run``."""
    recs = read_log(run_dir / "log.jsonl")
    seq = load_sequence(seq_dir)
    est = np.array([r["pose"] for r in recs])
    cov = np.array([r["cov_pose"] for r in recs])
    dr = np.array([r["dead_reckoning"] for r in recs])
    truth = seq.groundtruth[: len(recs)]
    logged = np.array([r["true_pose"] for r in recs])
    if not np.allclose(logged, truth, atol=1e-6):
        raise RuntimeError(f"{run_dir}: log true_pose differs from {seq_dir}/groundtruth.tum")
    nees = pose_nees(est, cov, truth)
    later = nees[1:]  # frame 0 is the prior: the true start, NEES 0
    nis = [v for r in recs for v in r["nis"]]
    return {
        "recs": recs, "nees": nees, "est": est, "truth": truth,
        "ate": ate_rmse(est, truth), "dr_ate": ate_rmse(dr, truth),
        "nees_mean": float(np.mean(later)),
        "inside": float(np.mean((later >= BOUNDS_1RUN[0]) & (later <= BOUNDS_1RUN[1]))),
        "above": float(np.mean(later > BOUNDS_1RUN[1])),
        "outliers": [(int(r["index"]), float(v)) for r, v in zip(recs, nees, strict=True) if v > BOUNDS_1RUN[1]],
        "nis_mean": float(np.mean(nis)) if nis else math.nan,
        "landmarks": max((r["n_landmarks"] for r in recs), default=0),
        "obs_per_frame": float(np.mean([len(r["observed"]) for r in recs])),
        "warnings": sum(len(r["warnings"]) for r in recs),
    }


def write_frames_csv(path: Path, ev: dict) -> None:
    """Per-frame figures: NEES, errors [mm, deg], σ, observations, NIS, warnings."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["index", "nees", "ex_mm", "ey_mm", "eth_deg", "sx_mm", "sy_mm", "sth_deg", "n_observed",
                    "n_new", "n_landmarks", "max_nis", "inflation", "warnings"])
        for r, n, e, t in zip(ev["recs"], ev["nees"], ev["est"], ev["truth"], strict=True):
            d = e - t
            d[2] = (d[2] + math.pi) % (2 * math.pi) - math.pi
            s = np.sqrt(np.diag(np.array(r["cov_pose"])))
            w.writerow([r["index"], f"{n:.3f}", f"{1e3 * d[0]:.1f}", f"{1e3 * d[1]:.1f}", f"{math.degrees(d[2]):.3f}",
                        f"{1e3 * s[0]:.1f}", f"{1e3 * s[1]:.1f}", f"{math.degrees(s[2]):.3f}", len(r["observed"]),
                        len(r["new"]), r["n_landmarks"], f"{max(r['nis'], default=0):.2f}", r["inflation"],
                        " | ".join(map(str, r["warnings"]))])


def run_scenario(name: str, frames: int, seed: int, out: Path, with_sim: bool, calibrate: bool,
                 config: list[str], bases: tuple[str, ...] = BASE_PHOTOS, reuse: bool = False) -> list[Row]:
    """Simulate, render and run scenario ``name`` into ``out/name`` (module docstring); ``reuse``: run on the
    folders an earlier call left there (of as many frames), without simulating or rendering again."""
    sc = load_scenario(name)
    n = min(frames, int(count_frames(sc.robot)))
    base = out / name
    sim_dir, pyb_dir = base / "sim", base / "pybullet"
    base.mkdir(parents=True, exist_ok=True)
    if reuse and all((d / "sequence.yaml").is_file() and len(load_sequence(d)) == n for d in (sim_dir, pyb_dir)):
        render_s, mismatch = math.nan, math.nan
    else:
        stablemarks("simulate", name, "--out", str(sim_dir), "--frames", str(n), "--seed", str(seed), "--force")
        if pyb_dir.exists():
            shutil.rmtree(pyb_dir)
        shutil.copytree(sim_dir, pyb_dir)
        compare = sorted({0, n // 4, n // 2, (3 * n) // 4, n - 1})
        render_s, mismatch = render_sequence(pyb_dir, sc, seed, base / "compare", compare, bases)
    rows = []
    for images, seq_dir in (("pybullet", pyb_dir), ("project", sim_dir)):
        if images == "project" and not with_sim:
            continue
        run_dir = base / f"run_{images}"
        if run_dir.exists():
            shutil.rmtree(run_dir)
        start = time.perf_counter()
        stablemarks("run", str(seq_dir), "--out", str(run_dir), "--no-figures", *config,
                    log=base / f"run_{images}.txt")
        run_s = time.perf_counter() - start
        ev = evaluate(run_dir, seq_dir)
        write_frames_csv(base / f"frames_{images}.csv", ev)
        rows.append(Row(name, images, n, 1e3 * ev["ate"], 1e3 * ev["dr_ate"], ev["nees_mean"], ev["inside"],
                        ev["above"], ev["nis_mean"], ev["landmarks"], ev["obs_per_frame"],
                        render_s if images == "pybullet" else math.nan, run_s,
                        mismatch if images == "pybullet" else math.nan, ev["warnings"], tuple(ev["outliers"])))
    if calibrate:
        res = subprocess.run([str(VENV_BIN / "stablemarks"), "calibrate-noise", str(pyb_dir), "--out",
                              str(base / "noise.yaml"), *config], capture_output=True, text=True)
        (base / "calibrate_noise.txt").write_text(f"exit {res.returncode}\n{res.stdout}{res.stderr}")
    return rows


HEADER = (f"{'scenario':9} {'images':8} {'frames':>6} {'ATE mm':>7} {'DR mm':>7} {'ratio':>5} {'NEES':>6} "
          f"{'inside':>6} {'above':>6} {'NIS':>5} {'lmks':>4} {'obs/fr':>6} {'render s':>8} {'run s':>6} "
          f"{'geom':>6} {'warn':>4}")


def format_row(r: Row) -> str:
    return (f"{r.scenario:9} {r.images:8} {r.frames:6d} {r.ate_mm:7.1f} {r.dr_ate_mm:7.1f} {r.ratio:5.2f} "
            f"{r.nees_mean:6.2f} {100 * r.inside:5.0f}% {100 * r.above:5.0f}% {r.nis_mean:5.2f} {r.landmarks:4d} "
            f"{r.obs_per_frame:6.1f} {r.render_s:8.1f} {r.run_s:6.1f} {100 * r.mismatch:5.2f}% {r.warnings:4d}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="+", help="built-in scenario names (office, lab, hall, ...)")
    parser.add_argument("--frames", type=int, default=60, help="frames per run (at most the scenario's path)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("/tmp/indep"), help="folder of the sequences and runs")
    parser.add_argument("--with-sim", action="store_true", help="also run the project-rendered folder")
    parser.add_argument("--calibrate-noise", action="store_true",
                        help="also run `stablemarks calibrate-noise` on the pybullet folder (slow)")
    parser.add_argument("--bases", default=",".join(BASE_PHOTOS),
                        help="skimage.data photographs tiled as the walls' base, comma-separated (default %(default)s)")
    parser.add_argument("--reuse", action="store_true",
                        help="run on the folders an earlier call left in --out (no simulating or rendering)")
    preset_arg(parser)  # passed on to `stablemarks run`
    parser.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                        help="passed to `stablemarks run` (repeatable)")
    args = parser.parse_args(argv)
    config = ([] if args.preset is None else ["--preset", args.preset]) + [a for s in args.set for a in ("--set", s)]
    print(f"pose NEES bounds of one run (3 dof, 95 %): {BOUNDS_1RUN}; geom: share of whole-labelled pixels of the "
          "left images where pybullet and the project's caster see different objects (worst frame)")
    print(HEADER, flush=True)
    for name in args.scenarios:
        for row in run_scenario(name, args.frames, args.seed, args.out, args.with_sim, args.calibrate_noise,
                                config, tuple(args.bases.split(",")), args.reuse):
            print(format_row(row), flush=True)
            if row.outliers:
                print(f"{'':19}frames above the bound (index: NEES): "
                      + ", ".join(f"{k}: {v:.1f}" for k, v in row.outliers), flush=True)


if __name__ == "__main__":
    main()
