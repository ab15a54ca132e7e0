"""Monte Carlo evaluation of the methods side by side on simulated scenarios (issue 6, DESIGN.md §5).

A *trial* is one simulated run of a scenario (:func:`stablemarks.sim.run.simulate_run`) with its own seed:
its own odometry noise, exposure jitter and sensor noise. The trials of a scenario take their seeds from
``numpy.random.SeedSequence(base).spawn(N)`` (:func:`trial_seeds`). Every method runs on the *same*
trials: the same true path, the same noisy odometry, the same per-frame noise streams and the same start
error. The filter's start pose is drawn from ``N(true start, cov0)`` (the trial seed's stream ``(2,)``),
so the start belief is a fair sample of its covariance and the NEES is χ² from the first frame on. Each
method commands its own head pan from its own belief (the closed loop of :func:`~stablemarks.online.run_online`),
as the robot would: when two methods believe different poses they look in slightly different directions,
and the images differ only by that pan. One task is one (scenario, trial, method); tasks run in parallel
through joblib (:func:`evaluate`).

Methods: those of :data:`stablemarks.methods.METHODS` and, when the optional ``gtsam`` extra is installed,
``gtsam_batch`` (:data:`SMOOTHER`): the batch smoother of :mod:`stablemarks.smoother` over the ``stablemarks``
run of the same trial — the same odometry, the same landmark priors and the full method's associations and
observations — solved by Levenberg–Marquardt: the accuracy reference the full method is compared with. It
runs in the same task as that trial's ``stablemarks`` run when both are asked for, else it makes that run
itself.

Metrics (per scenario and method; :mod:`stablemarks.metrics` defines NEES, NIS, bounds, ATE):

- ``nees_pose_mean`` — mean pose NEES over all frames and trials (3 dof); ``nees_pose_bounds`` — the 95 %
  bounds ``[χ²⁻¹(0.025; 3N)/N, χ²⁻¹(0.975; 3N)/N]`` of an N-trial average; ``nees_pose_fraction_inside`` —
  fraction of the frames whose N-trial average NEES lies inside those bounds; ``nees_pose_fraction_above`` —
  the fraction above them (overconfident; the rest of the frames outside lie below, cautious).
- ``nees_landmark_mean`` with ``nees_landmark_bounds`` — 1-dof NEES along the true feature's wall of each
  landmark at the end of its run (for a wall landmark ``(s − s_true)² / var_s`` with ``s_true`` measured
  from the landmark's own edge), averaged over the M landmarks of all trials, bounds for M values
  (landmarks of one run share their boundary's error, so these bounds are narrower than an independent
  test would allow).
- ``nis_mean`` with ``nis_bounds`` — 2-dof NIS of every observation of every trial (M values, bounds for
  M); the 99 % association gate truncates the NIS, which biases its mean slightly low.
- ``ate_rmse`` — mean over trials of the RMS planar position error [m]; ``ate_ratio_dead_reckoning`` —
  its ratio to the dead-reckoning's mean ATE in the same trials; ``final_error_mean`` [m].
- ``landmark_error_mean`` — mean planar distance [m] at the end of the run between each landmark with a
  known true feature and that feature.
- ``selection_precision`` — of all landmarks the method entered (the selected ones, in the first view and
  in later frames), the fraction modelled from a true on-plane feature: the true image edge of the same
  wall nearest to the candidate's modelled position within ``max(3σ_s, 5 cm)`` (for points, any wall
  within 10 cm) is a ``feature`` edge (not a plane's ``boundary``) of a reference plane of the map.
  Landmarks matched to no true edge count against it.
- ``selection_recall`` — of the true on-plane features *away from plane boundaries* (more than
  :data:`BOUNDARY_MARGIN` along the wall from its free edges) that were *in view* in some frame (visible
  in both images together with a free edge of their wall, the method's precondition for modelling), the
  fraction some landmark was modelled from.
- ``reobservation_selected`` / ``reobservation_rejected`` — the stability claim: the re-observation rate
  (:func:`stablemarks.metrics.reobservation`: associated / later frames where the true feature is in view
  and unoccluded), pooled over the landmarks whose true feature the full method *selected* in that trial
  versus those it *rejected* and never selected. Rejected candidates never enter the full method's filter,
  so their rate is measured where they do enter one: in the ``plane_no_selection`` run of the same trial,
  which models the same candidates and takes all of them (the row ``stablemarks`` reports that run's rate
  for the rejected ones; it is NaN when ``plane_no_selection`` was not run). Each other method's row gives
  the rates of its own landmarks of the two groups.
- ``time_per_frame`` — mean wall time [s] of the method's own work in a frame: front end, association and
  update, modelling and selection (the loop's ``total`` minus its ``predict`` stage, which holds the
  odometry prediction and the simulator's rendering); for ``gtsam_batch`` the smoothing time (graph,
  optimisation and marginals) divided by the number of frames, without the run it smooths.

For ``gtsam_batch`` the pose NEES uses the smoother's marginal covariances and the landmark NEES and error
its smoothed landmarks; it has no NIS, and the selection and re-observation keys, which would only repeat
those of the ``stablemarks`` run it smooths, are NaN.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from .config import Config
from .errors import InputError, expected
from .frames import Frame
from .localizer import Estimate, Localizer
from .methods import METHODS
from .metrics import (
    along_wall_nees,
    ate_rmse,
    chi2_bounds,
    fraction_above,
    fraction_inside,
    pose_nees,
    position_errors,
    reobservation,
)
from .online import OnlineResult, run_online
from .sim.render import renderer_for
from .sim.run import Run, simulate_run
from .sim.scenario import Scenario, load_scenario
from .sim.source import SimulatedSource
from .smoother import GTSAM_HINT, gtsam_available

SMOOTHER = "gtsam_batch"
"""The evaluation-only method: the batch smoother over the ``stablemarks`` run (needs the ``gtsam`` extra)."""

BACKENDS = ("loky", "dask", "ray")
"""joblib backends :func:`evaluate` runs on; ``dask`` and ``ray`` need the optional extras of the same name."""

BOUNDARY_MARGIN = 0.15
"""Distance along the wall from a free edge [m] inside which a true feature does not count for recall: the
near-boundary region the selection rejects (3σ of the boundary at 4–6 m in the lab is 0.11–0.16 m)."""

DEFAULT_COV0 = np.diag([0.05, 0.05, np.deg2rad(1.0)]) ** 2
"""Covariance of the start pose belief (σ = 5 cm, 5 cm, 1°), as in :func:`~stablemarks.online.run_online`."""

SUMMARY_KEYS = (
    "trials", "frames", "nees_pose_mean", "nees_pose_bounds", "nees_pose_fraction_inside", "nees_pose_fraction_above",
    "nees_landmark_mean", "nees_landmark_bounds", "nees_landmark_count", "nis_mean", "nis_bounds", "nis_count",
    "ate_rmse", "ate_ratio_dead_reckoning", "final_error_mean", "landmark_error_mean", "landmarks_mean",
    "selection_precision", "selection_recall", "reobservation_selected", "reobservation_rejected",
    "time_per_frame",
)


# ------------------------------------------------------------------ trials
@dataclass(frozen=True)
class Trial:
    """One task of an evaluation: a method on one simulated run of a scenario.

    ``scenario``: built-in name or YAML path; ``index``: trial number; ``seed``: the run's seed
    (:func:`trial_seeds`); ``frames``: keep only the first ``frames`` frames (None: all); ``cov0`` (3, 3):
    start pose covariance [m², rad²].
    """

    scenario: str
    index: int
    seed: int
    method: str
    frames: int | None = None
    cov0: np.ndarray = field(default_factory=lambda: DEFAULT_COV0.copy())
    config: Config = field(default_factory=Config)
    pan_policy: str | None = None
    """The pan policy the method's head follows (``pan.policy``); None: the scenario's."""
    tag: str = ""
    """Appended to the method's name in the results (``stablemarks@information``), to tell policies apart."""

    @property
    def label(self) -> str:
        """The method's name in the results."""
        return self.method + self.tag


def trial_seeds(base: int, n: int) -> list[int]:
    """``n`` independent run seeds from ``SeedSequence(base).spawn(n)`` (one 64-bit integer each)."""
    children = np.random.SeedSequence(int(base)).spawn(int(n))
    return [int(c.generate_state(1, dtype=np.uint64)[0]) for c in children]


def available_methods() -> tuple[str, ...]:
    """The methods this installation evaluates: :data:`stablemarks.methods.METHODS`, then :data:`SMOOTHER`
    when gtsam is importable. The default method list of :func:`make_trials`."""
    return tuple(METHODS) + ((SMOOTHER,) if gtsam_available() else ())


def check_methods(methods: Iterable[str]) -> tuple[str, ...]:
    """Validate method names (:func:`available_methods`); duplicates dropped, order kept."""
    known = available_methods()
    out = tuple(dict.fromkeys(methods))
    if not out:
        raise InputError(expected(f"at least one of {', '.join(known)}", "none", where="methods"))
    for m in out:
        if m not in known:
            hint = f" ({GTSAM_HINT})" if m == SMOOTHER else ""
            raise InputError(expected(f"one of {', '.join(known)}", m, where="methods") + hint)
    return out


def make_trials(scenarios: Sequence[str], n_trials: int, methods: Sequence[str] | None = None, *,
                seed: int | None = None, frames: int | None = None, cov0=None,
                config: Config = Config(), pan_policies: Sequence[str] | None = None) -> list[Trial]:
    """All tasks of an evaluation, scenario by scenario, trial by trial, method by method (and pan policy).

    Loads (validates) every scenario first. ``methods``: default :func:`available_methods`. ``seed``: base of
    :func:`trial_seeds` (default: each scenario's own ``seed``). ``pan_policies``: run every method with each
    of these pan policies (default: the scenario's); with more than one, the results name the method
    ``method@policy``.
    """
    from .viewing import PAN_POLICIES

    policies = list(pan_policies or [None])
    for p in policies:
        if p is not None and p not in PAN_POLICIES:
            raise InputError(expected(f"one of {', '.join(PAN_POLICIES)}", p, where="pan_policies"))
    if isinstance(n_trials, bool) or not isinstance(n_trials, int) or n_trials < 1:
        raise InputError(expected("a positive number of trials", n_trials, where="trials"))
    if frames is not None and (isinstance(frames, bool) or not isinstance(frames, int) or frames < 1):
        raise InputError(expected("a positive number of frames", frames, where="frames"))
    methods = check_methods(available_methods() if methods is None else methods)
    cov0 = DEFAULT_COV0.copy() if cov0 is None else np.asarray(cov0, dtype=float)
    if cov0.shape != (3, 3) or not np.all(np.isfinite(cov0)) or np.any(np.linalg.eigvalsh(cov0) <= 0):
        raise InputError(expected("a positive definite (3, 3) covariance", cov0.tolist(), where="cov0"))
    loaded = [load_scenario(s) for s in scenarios]
    if not loaded:
        raise InputError(expected("at least one scenario", "none", where="scenarios"))
    out = []
    for name, sc in zip(scenarios, loaded, strict=True):
        for i, s in enumerate(trial_seeds(sc.seed if seed is None else seed, n_trials)):
            out += [Trial(str(name), i, s, m, frames, cov0, config, p, f"@{p}" if len(policies) > 1 else "")
                    for p in policies for m in methods]
    return out


def truncate_run(run: Run, n: int | None) -> Run:
    """The first ``n`` frames of a run (all of them for None); images depend only on the seed and index."""
    if n is None or n >= len(run):
        return run
    return replace(run, poses=run.poses[:n], odometry=run.odometry[:n], dead_reckoning=run.dead_reckoning[:n],
                   pans=run.pans[:n])


def start_belief(run: Run, cov0) -> np.ndarray:
    """The filter's start pose of a trial: the true start plus an error drawn from ``N(0, cov0)`` (the run
    seed's stream ``(2,)``), so that the start belief is a fair sample of its covariance."""
    rng = np.random.default_rng(np.random.SeedSequence(run.seed, spawn_key=(2,)))
    return run.poses[0].as_array() + np.linalg.cholesky(cov0) @ rng.standard_normal(3)


def _match_truth(truth, c, tol_px: float = 2.0) -> str | None:
    """Id of the true image edge that candidate ``c`` was measured from: on the same wall, some of its rows seen
    in both images, within ``tol_px`` of the candidate's columns in both images (nearest first), and within
    max(3σ, 5 cm) of its position.

    Some rows, not :data:`~stablemarks.sim.truth.VISIBLE_FRACTION` of them (the rule of an edge in view, for
    recall): a feature mostly hidden behind clutter is still the feature where its top shows above it (the
    storeroom's pipe behind the cabinet, a fifth of its height seen: its two lines, entered at the true edges'
    columns to 0.1 px, counted against the selection's precision)."""
    best, best_d = None, 2.0 * tol_px
    for e in truth.edges:
        if e.wall != c.plane_id or not (e.in_view_l and e.in_view_r and e.visible_fraction_l > 0
                                        and e.visible_fraction_r > 0):
            continue
        du = abs(e.u_l - c.u_left) + abs(e.u_r - c.u_right)
        if du <= best_d and max(abs(e.u_l - c.u_left), abs(e.u_r - c.u_right)) <= tol_px:
            best, best_d = e, du
    if best is None or np.hypot(best.x - c.P[0], best.y - c.P[1]) > max(3.0 * c.sigma_s, 0.05):
        return None
    return best.id


class TruthObserver:
    """The evaluation's ground-truth bookkeeping, an observer of :func:`~stablemarks.online.run_online`.

    After every step it records which true feature each new landmark was modelled from (``truth_of``:
    landmark id → true edge id; a wall landmark by its candidate's image columns, :func:`_match_truth`; a
    point landmark by the nearest visible true edge within 10 cm), which true features the selection
    rejected and why (``rejected_truth``), the true features in view in both images per frame
    (``visible``), and every true edge seen (``edges``: id → :class:`~stablemarks.sim.truth.EdgeTruth`).
    Frames without truth (recordings) leave it empty.
    """

    def __init__(self) -> None:
        self.truth_of: dict[int, str] = {}
        self.rejected_truth: dict[str, str] = {}
        self.visible: list[list[str]] = []
        self.edges: dict = {}

    def __call__(self, frame: Frame, est: Estimate, localizer: Localizer) -> None:
        truth = frame.truth
        if truth is None:
            self.visible.append([])
            return
        if not self.edges:
            self.edges = {e.id: e for e in truth.edges}
        if est.model is not None:
            for c in est.model.candidates:
                tid = _match_truth(truth, c)
                if tid is not None and not c.selected:
                    self.rejected_truth.setdefault(tid, c.reason)
        for c, i in zip(est.entered.candidates, est.entered.ids, strict=True):
            tid = _match_truth(truth, c) if c is not None else self._nearest(truth, localizer.ekf.landmark(i).position)
            if tid is not None:
                self.truth_of[i] = tid
        self.visible.append([e.id for e in truth.edges if e.visible_l and e.visible_r])

    @staticmethod
    def _nearest(truth, position, radius: float = 0.1) -> str | None:
        best, best_d = None, radius
        for e in truth.edges:
            if e.visible_l and e.visible_r:
                d = float(np.hypot(e.x - position[0], e.y - position[1]))
                if d < best_d:
                    best, best_d = e.id, d
        return best

    def result(self, result: OnlineResult) -> OnlineResult:
        """``result`` with this observer's ground truth filled in."""
        return replace(result, truth_of=dict(self.truth_of), rejected_truth=dict(self.rejected_truth),
                       visible_truth=[list(v) for v in self.visible])


def run_trial(trial: Trial) -> dict:
    """Run one task and measure it; returns a JSON-ready dict (one line of ``trials.jsonl``).

    Keys: ``scenario, trial, seed, method, frames``; per frame ``nees_pose``, ``position_error`` [m];
    ``nis`` (every observation); ``ate_rmse``, ``final_error`` [m]; ``landmarks`` (one dict per landmark
    with a known true feature: ``id, truth, nees, error`` [m], ``reobserved`` [associated, visible]);
    ``n_landmarks`` (all entered), ``n_true_features`` (entered from a true on-plane feature),
    ``found`` / ``eligible`` (true features for recall), ``selected_truth``, ``rejected_truth`` (true edge
    ids the method's selection rules took / rejected); ``time_per_frame`` [s] and per-stage means.
    """
    return run_trials([trial])[0]


def run_trials(trials: Sequence[Trial]) -> list[dict]:
    """Run the tasks of one simulated run (same scenario, seed, frames, start covariance and configuration)
    and measure each (:func:`run_trial`); :data:`SMOOTHER` smooths the ``stablemarks`` run, made once."""
    if not trials:
        return []
    first = trials[0]
    same = (first.scenario, first.seed, first.frames, first.cov0.tobytes(), first.config, first.pan_policy)
    for t in trials[1:]:
        if (t.scenario, t.seed, t.frames, t.cov0.tobytes(), t.config, t.pan_policy) != same:
            raise InputError(expected(f"tasks of one run ({first.scenario} seed {first.seed})",
                                      f"{t.scenario} seed {t.seed}", where="run_trials"))
    try:
        scenario = load_scenario(first.scenario)
        run = truncate_run(simulate_run(scenario, first.seed), first.frames)
    except Exception as exc:  # noqa: BLE001 - every task of this run fails alike, the others go on
        return [failed_result(t, first.scenario, exc) for t in trials]
    runs: dict[str, tuple[TruthObserver, OnlineResult] | Exception] = {}
    renderer = None  # one for the methods of this run: each frame rendered once (_SharedRenderer)

    def online(method: str) -> tuple[TruthObserver, OnlineResult]:
        nonlocal renderer
        if method not in runs:
            try:
                if renderer is None:
                    renderer = _SharedRenderer(renderer_for(scenario))
                source = SimulatedSource(run, renderer=renderer)
                truth = TruthObserver()
                config = first.config.with_source_defaults(source.config_defaults)
                if first.pan_policy is not None:
                    config = config.with_overrides({"pan": {"policy": first.pan_policy}}, "pan policy")
                result = run_online(source, start_pose=start_belief(run, first.cov0), start_cov=first.cov0,
                                    config=config, method=method, observers=[truth])
                runs[method] = truth, truth.result(result)
            except Exception as exc:  # noqa: BLE001 - recorded once, raised for every task that needs the run
                runs[method] = exc
        done = runs[method]
        if isinstance(done, Exception):
            raise done
        return done

    out = []
    for t in trials:
        try:
            if t.method == SMOOTHER:
                try:
                    base = online("stablemarks")
                except Exception as exc:  # noqa: BLE001
                    raise TrialFailure(f"the stablemarks run it smooths failed: {_describe(exc)}") from exc
                out.append(_smoothed_measures(t, scenario, *base))
            else:
                out.append(_online_measures(t, scenario, *online(t.method)))
        except Exception as exc:  # noqa: BLE001 - one failing task must not end the evaluation
            out.append(failed_result(t, scenario.name, exc))
    return out


class _SharedRenderer:
    """A scenario's renderer shared by the methods of one run (:func:`run_trials`): each stereo pair is rendered
    once and handed to every method that asks for the same frame — the same pose, pan and random stream (a
    frame's images depend on nothing else), so the same images as rendering again. A method whose head
    points elsewhere gets its own rendering. The pairs are read-only; ``renders`` counts the renderings."""

    def __init__(self, renderer) -> None:
        self.renderer = renderer
        self.scenario = renderer.scenario
        self.renders = 0
        self._frames: dict[tuple, object] = {}

    def render(self, X, pan: float, rng: np.random.Generator):
        key = (np.asarray(X, dtype=float).tobytes(), float(pan), repr(rng.bit_generator.state))
        frame = self._frames.get(key)
        if frame is None:
            frame = self.renderer.render(X, pan, rng)
            for img in (frame.left, frame.right):
                img.setflags(write=False)  # shared between the methods: none may change it
            self._frames[key] = frame
            self.renders += 1
        return frame

    def truth(self, X, pan: float):
        """The frame's truth without its images (:meth:`~stablemarks.sim.render.Renderer.truth`)."""
        return self.renderer.truth(X, pan)


class TrialFailure(RuntimeError):
    """A task of the evaluation could not be measured (its message says why)."""


def _describe(exc: BaseException) -> str:
    """``ExceptionClass: message`` of a task's failure, on one line (:func:`~stablemarks.errors.one_line`)."""
    from .errors import one_line

    if isinstance(exc, TrialFailure):
        return one_line(str(exc), 500)
    text = str(exc).strip()
    return one_line(f"{type(exc).__name__}: {text}" if text else type(exc).__name__, 500)


def failed_result(trial: Trial, scenario: str, exc: BaseException) -> dict:
    """The line of ``trials.jsonl`` for a task that failed: ``scenario, trial, seed, method`` and ``error`` (the
    exception's class and message); it has none of the measures and :func:`summarize` leaves it out."""
    return {"scenario": scenario, "trial": trial.index, "seed": trial.seed, "method": trial.label,
            "error": _describe(exc)}


def failures(results: Sequence[dict]) -> list[dict]:
    """The tasks of ``results`` that failed (:func:`failed_result`), in order."""
    return [r for r in results if r.get("error") is not None]


def _online_measures(trial: Trial, scenario: Scenario, source: TruthObserver, result: OnlineResult) -> dict:
    """:func:`run_trial`'s dict for an on-line method's run."""
    stages: dict[str, list[float]] = {}
    for r in result.records:
        for key, v in r.timings.items():
            stages.setdefault(key, []).append(v)
    landmarks = [result.ekf.landmark(lid) for lid in result.ekf.landmark_ids]
    estimates = {lm.id: (lm.position, lm.cov2d) for lm in landmarks}
    return _measures(trial, scenario, source, result, result.poses, result.covs, estimates,
                     nis=[v for r in result.records for v in r.nis],
                     time_per_frame=float(np.mean(np.subtract(stages["total"], stages["predict"]))),
                     stage_times={k: float(np.mean(v)) for k, v in stages.items()})


def _smoothed_measures(trial: Trial, scenario: Scenario, source: TruthObserver, result: OnlineResult) -> dict:
    """:func:`run_trial`'s dict for :data:`SMOOTHER` over the ``stablemarks`` run ``result``."""
    from .smoother import batch_smooth

    start = time.perf_counter()
    smoothed = batch_smooth(result, scenario.camera, trial.config)
    per_frame = (time.perf_counter() - start) / len(result.records)
    # a landmark the smoother could not constrain has no marginal (smoother.WEAK_LANDMARK_SIGMA): left out
    estimates = {lid: (lm.position, lm.cov2d) for lid, lm in smoothed.landmarks.items() if lm.cov2d is not None}
    out = _measures(trial, scenario, source, result, smoothed.poses, smoothed.cov_poses, estimates, nis=[],
                    time_per_frame=per_frame, stage_times={"smooth": per_frame})
    out["rejected_truth"] = []  # the full method's selection, not the smoother's
    return out


def _measures(trial: Trial, scenario: Scenario, source: TruthObserver, result: OnlineResult, poses, covs,
              estimates: dict, *, nis: list[float], time_per_frame: float, stage_times: dict) -> dict:
    """The measures of :func:`run_trial` for poses (K, 3) with covariances (K, 3, 3) and landmark estimates
    ``{id: (position (2,), cov2d (2, 2))}`` over the run ``result`` (its landmarks, truth and records)."""
    T = result.true_poses
    err = position_errors(poses, T)
    on_plane = _on_plane_features(scenario, source.edges)
    eligible = _eligible_features(result, scenario, source.edges, on_plane)
    return {
        "scenario": scenario.name, "trial": trial.index, "seed": trial.seed, "method": trial.label,
        "frames": len(result.records),
        "nees_pose": pose_nees(poses, covs, T).tolist(), "position_error": err.tolist(), "nis": nis,
        "ate_rmse": ate_rmse(poses, T), "final_error": float(err[-1]),
        "landmarks": _landmark_measures(result, scenario, source.edges, estimates),
        "n_landmarks": sum(len(r.new) for r in result.records),
        "n_true_features": sum(1 for tid in result.truth_of.values() if tid in on_plane),
        "eligible": sorted(eligible), "found": sorted(eligible & set(result.truth_of.values())),
        "selected_truth": sorted(set(result.truth_of.values())) if trial.method == "stablemarks" else [],
        "rejected_truth": sorted(result.rejected_truth),
        "time_per_frame": time_per_frame, "stage_times": stage_times,
    }


def _on_plane_features(scenario: Scenario, edges: dict) -> set[str]:
    """Ids of the true ``feature`` edges on walls that are reference planes of the robot's map."""
    refs = {p.id for p in scenario.map.planes if p.reference}
    return {e.id for e in edges.values() if e.kind == "feature" and e.wall in refs}


def _landmark_measures(result, scenario: Scenario, edges: dict, estimates: dict) -> list[dict]:
    """Along-wall NEES, position error and re-observation of each landmark with a known true feature;
    ``estimates``: ``{landmark id: (position (2,), cov2d (2, 2))}``."""
    reobs = reobservation(result)
    out = []
    for lid, tid in sorted(result.truth_of.items()):
        if lid not in estimates or tid not in edges:
            continue
        position, cov2d = estimates[lid]
        e = edges[tid]
        true_xy = np.array([e.x, e.y])
        direction = scenario.wall(e.wall).plane.direction
        nees = along_wall_nees(position, cov2d, true_xy, direction)[0]
        out.append({"id": int(lid), "truth": tid, "nees": float(nees),
                    "error": float(np.hypot(*(position - true_xy))),
                    "reobserved": list(reobs.get(lid, (0, 0)))})
    return out


def _eligible_features(result, scenario: Scenario, edges: dict, on_plane: set[str]) -> set[str]:
    """True on-plane features away from boundaries seen in some frame together with a free edge of their wall."""
    far = set()
    for tid in on_plane:
        e = edges[tid]
        plane = scenario.wall(e.wall).plane
        gaps = [e.s if fe == "p1" else plane.length - e.s for fe in plane.free_edges]
        if gaps and min(gaps) > BOUNDARY_MARGIN:
            far.add(tid)
    out = set()
    for r in result.records:
        vis = set(result.visible_truth[r.index])
        for tid in far & vis:
            wall = edges[tid].wall
            if any(f"{wall}-{fe}" in vis for fe in scenario.wall(wall).plane.free_edges):
                out.add(tid)
    return out


# ---------------------------------------------------------------- running
@contextlib.contextmanager
def _backend(backend: str, jobs: int, address: str | None):
    """The joblib backend context: loky as is; dask through a ``distributed`` client (a local cluster of
    ``jobs`` workers unless ``address`` names a scheduler); ray through ``ray.util.joblib``."""
    if backend not in BACKENDS:
        raise InputError(expected(f"one of {', '.join(BACKENDS)}", backend, where="backend"))
    if backend == "loky":
        yield
        return
    hint = f"the {backend} backend needs its optional extra: pip install 'stablemarks[{backend}]'"
    workers = jobs if jobs > 0 else None  # -1: as many as the machine has
    if backend == "dask":
        try:
            from dask.distributed import Client
        except ImportError:
            raise InputError(hint) from None
        client = Client(address) if address else Client(n_workers=workers, threads_per_worker=1,
                                                         processes=True, dashboard_address=None)
        try:
            yield
        finally:
            client.close()
        return
    try:
        import ray
        from ray.util.joblib import register_ray
    except ImportError:
        raise InputError(hint) from None
    register_ray()
    started = not ray.is_initialized()
    if started:
        ray.init(address=address, num_cpus=None if address else workers, include_dashboard=False,
                 log_to_driver=False)
    try:
        yield
    finally:
        if started:
            ray.shutdown()


def check_backend(backend: str) -> None:
    """Raise :class:`InputError` (with the ``pip install`` line) unless ``backend`` can run here."""
    if backend not in BACKENDS:
        raise InputError(expected(f"one of {', '.join(BACKENDS)}", backend, where="backend"))
    module = {"loky": "joblib", "dask": "dask.distributed", "ray": "ray.util.joblib"}[backend]
    import importlib.util

    try:
        found = importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        found = False
    if not found:
        what = "joblib" if backend == "loky" else f"'stablemarks[{backend}]'"
        raise InputError(f"backend {backend!r} is not installed: pip install {what}")


def _parallel(Parallel):
    """A joblib ``Parallel`` that yields results as they finish where the backend can (ray cannot: there they
    come in order)."""
    for mode in ("generator_unordered", "generator"):
        try:
            return Parallel(return_as=mode)
        except ValueError:
            continue
    return Parallel()


def _bundles(trials: Sequence[Trial]) -> list[list[Trial]]:
    """The jobs: each task alone, except that a trial's ``stablemarks`` and :data:`SMOOTHER` tasks share one
    job (the smoother reuses that run)."""
    jobs: dict[tuple, list[Trial]] = {}
    for t in trials:
        key = (t.scenario, t.index, t.pan_policy) if t.method in ("stablemarks", SMOOTHER) else \
            (t.scenario, t.index, t.pan_policy, t.method)
        jobs.setdefault(key, []).append(t)
    return list(jobs.values())


def evaluate(trials: Sequence[Trial], *, jobs: int = 1, backend: str = "loky", address: str | None = None,
             progress: Callable[[int, int, dict], None] | None = None) -> list[dict]:
    """Run the tasks in parallel (joblib ``Parallel(n_jobs=jobs)`` on ``backend``) and return their
    results (:func:`run_trial`) sorted by scenario, trial and method order. A trial's ``stablemarks`` and
    :data:`SMOOTHER` tasks run as one job (:func:`run_trials`). ``progress(done, total, result)`` is called
    in this process as each task finishes."""
    from joblib import Parallel, delayed, parallel_config

    check_backend(backend)
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs == 0 or jobs < -1:
        raise InputError(expected("a positive number of jobs (or -1 for all cores)", jobs, where="jobs"))
    results = []
    with _backend(backend, jobs, address), parallel_config(backend=backend, n_jobs=jobs):
        run_all = _parallel(Parallel)
        for batch in run_all(delayed(run_trials)(b) for b in _bundles(trials)):
            for res in batch:
                results.append(res)
                if progress is not None:
                    progress(len(results), len(trials), res)
    order = {(t.scenario, t.index, t.label): k for k, t in enumerate(trials)}
    names = {t.scenario: load_scenario(t.scenario).name for t in trials}
    rank = {(names[s], i, m): k for (s, i, m), k in order.items()}

    def key(r):  # a task whose scenario failed to load carries the name it was given
        k = (r["scenario"], r["trial"], r["method"])
        return rank.get(k, order.get(k, len(order)))

    return sorted(results, key=key)


# ------------------------------------------------------------- aggregation
def _mean(values) -> float:
    v = np.asarray(list(values), dtype=float)
    return float(np.mean(v)) if v.size else float("nan")


def _rate(pairs) -> float:
    pairs = list(pairs)
    n = sum(b for _, b in pairs)
    return sum(a for a, _ in pairs) / n if n else float("nan")


def summarize(results: Sequence[dict]) -> dict:
    """Aggregate per-trial results (:func:`run_trial`) into ``{scenario: {method: {key: value}}}`` with the
    keys of :data:`SUMMARY_KEYS` (definitions in the module docstring) plus ``nees_pose_time`` (per frame,
    the N-trial average pose NEES)."""
    groups: dict[str, dict[str, list[dict]]] = {}
    for r in results:
        if r.get("error") is not None:  # a failed task (failed_result): reported, not measured
            continue
        groups.setdefault(r["scenario"], {}).setdefault(r["method"], []).append(r)
    out: dict = {}
    for scen, by_method in groups.items():
        out[scen] = {}

        def of(base: str, suffix: str, by_method=by_method) -> list[dict]:
            """The results of ``base`` run with the same pan policy (``base@POLICY``), else ``base``'s."""
            return by_method.get(base + suffix, by_method.get(base, []))

        for method, rs in by_method.items():
            base, at, policy = method.partition("@")
            suffix = at + policy
            full = {r["trial"]: r for r in of("stablemarks", suffix)}
            nosel = {r["trial"]: r for r in of("plane_no_selection", suffix)}
            selected = {t: set(r["selected_truth"]) for t, r in full.items()}
            rejected = {t: set(r["rejected_truth"]) - selected[t] for t, r in full.items()}
            dr = {r["trial"]: r["ate_rmse"] for r in of("dead_reckoning", suffix)}
            rs = sorted(rs, key=lambda r: r["trial"])
            n = len(rs)
            frames = min(r["frames"] for r in rs)
            nees_t = np.array([r["nees_pose"][:frames] for r in rs]).mean(axis=0)
            b_pose = chi2_bounds(n, 3)
            lm_nees = [lm["nees"] for r in rs for lm in r["landmarks"]]
            nis = [v for r in rs for v in r["nis"]]

            def group_rate(trials_rs, sets):
                return _rate(lm["reobserved"] for r in trials_rs if r["trial"] in sets
                             for lm in r["landmarks"] if lm["truth"] in sets[r["trial"]])

            rej_source = [nosel[r["trial"]] for r in rs if r["trial"] in nosel] if base == "stablemarks" else rs
            ate = _mean(r["ate_rmse"] for r in rs)
            ate_dr = _mean(dr[r["trial"]] for r in rs if r["trial"] in dr)
            out[scen][method] = {
                "trials": n,
                "frames": frames,
                "nees_pose_mean": _mean(v for r in rs for v in r["nees_pose"]),
                "nees_pose_bounds": list(b_pose),
                "nees_pose_fraction_inside": fraction_inside(nees_t, b_pose),
                "nees_pose_fraction_above": fraction_above(nees_t, b_pose[1]),
                "nees_landmark_mean": _mean(lm_nees),
                "nees_landmark_bounds": list(chi2_bounds(len(lm_nees), 1)) if lm_nees else [math.nan, math.nan],
                "nees_landmark_count": len(lm_nees),
                "nis_mean": _mean(nis),
                "nis_bounds": list(chi2_bounds(len(nis), 2)) if nis else [math.nan, math.nan],
                "nis_count": len(nis),
                "ate_rmse": ate,
                "ate_ratio_dead_reckoning": ate / ate_dr if ate_dr > 0 else math.nan,
                "final_error_mean": _mean(r["final_error"] for r in rs),
                "landmark_error_mean": _mean(lm["error"] for r in rs for lm in r["landmarks"]),
                "landmarks_mean": _mean(r["n_landmarks"] for r in rs),
                "selection_precision": _ratio(sum(r["n_true_features"] for r in rs), sum(r["n_landmarks"] for r in rs)),
                "selection_recall": _ratio(sum(len(r["found"]) for r in rs), sum(len(r["eligible"]) for r in rs)),
                "reobservation_selected": group_rate(rs, selected),
                "reobservation_rejected": group_rate(rej_source, rejected),
                "time_per_frame": _mean(r["time_per_frame"] for r in rs),
                "nees_pose_time": nees_t.tolist(),
            }
            if base in ("dead_reckoning", SMOOTHER):
                for key in ("selection_precision", "selection_recall", "reobservation_selected",
                            "reobservation_rejected"):
                    out[scen][method][key] = math.nan
    return out


def _ratio(a: float, b: float) -> float:
    return a / b if b else math.nan


def summary_rows(summary: dict) -> list[dict]:
    """Flat rows (scenario, method, scalar keys; bounds as ``_lo`` / ``_hi``) for ``summary.csv``."""
    rows = []
    for scen, by_method in summary.items():
        for method, s in by_method.items():
            row = {"scenario": scen, "method": method}
            for key in SUMMARY_KEYS:
                v = s[key]
                if isinstance(v, list):
                    row[f"{key}_lo"], row[f"{key}_hi"] = v
                else:
                    row[key] = v
            rows.append(row)
    return rows


def summary_csv(summary: dict) -> str:
    """``summary.csv`` text."""
    rows = summary_rows(summary)
    buf = io.StringIO()
    if rows:
        writer = csv.DictWriter(buf, fieldnames=list(rows[0]), lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
    return buf.getvalue()


def _json_safe(obj):
    """NaN and infinities become None (strict JSON)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_json_safe(v) for v in obj]
    return obj


def trials_jsonl(results: Sequence[dict]) -> str:
    """``trials.jsonl`` text: one strict-JSON line per task."""
    return "".join(json.dumps(_json_safe(r), allow_nan=False) + "\n" for r in results)


def summary_json(summary: dict) -> str:
    """``summary.json`` text (strict JSON: NaN as null)."""
    return json.dumps(_json_safe(summary), indent=1, allow_nan=False)


# ------------------------------------------------------------------- goals
@dataclass(frozen=True)
class Goal:
    """One goal of issue 6 checked on a summary: ``value`` against ``target`` (``met`` None: not measured)."""

    scenario: str
    name: str
    value: str
    target: str
    met: bool | None


GOALS_MIN_TRIALS = 20
"""The issue's goals are stated for at least this many trials per scenario, over every frame."""


def check_goals(summary: dict) -> list[Goal]:
    """The issue's goals for the full method on each scenario of ``summary``: for ``stablemarks`` and, when the
    evaluation compared pan policies, for each ``stablemarks@POLICY`` (against the references run with the same
    policy, ``gtsam_batch@POLICY`` and ``all_segments@POLICY``); the policy is named after the scenario."""
    goals = []
    for scen, by_method in summary.items():
        for method, s in by_method.items():
            if method != "stablemarks" and not method.startswith("stablemarks@"):
                continue
            suffix = method[len("stablemarks"):]
            label = scen if not suffix else f"{scen} {suffix}"
            goals += _goals_of(label, scen, s, by_method.get(SMOOTHER + suffix), by_method.get("all_segments" + suffix))
    return goals


def _goals_of(label: str, scen: str, s: dict, ref: dict | None, a: dict | None) -> list[Goal]:
    goals = []

    def add(name, value, target, met):
        finite = isinstance(value, float) and math.isfinite(value)
        goals.append(Goal(label, name, f"{value:.3g}" if finite else "n/a", target, bool(met) if finite else None))

    add("pose NEES frames inside 95 % bounds", s["nees_pose_fraction_inside"], "≥ 0.90",
        s["nees_pose_fraction_inside"] >= 0.9)
    lo, hi = s["nis_bounds"]
    add("NIS mean inside its bounds", s["nis_mean"], f"[{lo:.3g}, {hi:.3g}]" if s["nis_count"] else "—",
        s["nis_count"] and lo <= s["nis_mean"] <= hi)
    lo, hi = s["nees_landmark_bounds"]
    add("landmark NEES mean inside its bounds", s["nees_landmark_mean"],
        f"[{lo:.3g}, {hi:.3g}]" if s["nees_landmark_count"] else "—",
        s["nees_landmark_count"] and lo <= s["nees_landmark_mean"] <= hi)
    limit = 0.2 if scen == "loop" else 0.5
    add("ATE / dead reckoning", s["ate_ratio_dead_reckoning"], f"≤ {limit}", s["ate_ratio_dead_reckoning"] <= limit)
    add("selection precision", s["selection_precision"], "≥ 0.95", s["selection_precision"] >= 0.95)
    add("selection recall", s["selection_recall"], "≥ 0.80", s["selection_recall"] >= 0.8)
    add("re-observation of selected landmarks", s["reobservation_selected"], "≥ 0.95",
        s["reobservation_selected"] >= 0.95)
    rej = s["reobservation_rejected"]
    add("re-observation selected − rejected", s["reobservation_selected"] - rej, "> 0",
        s["reobservation_selected"] > rej)
    if ref is not None:
        ratio = _ratio(s["ate_rmse"], ref["ate_rmse"])
        add(f"ATE / {SMOOTHER}'s ATE", ratio, "≤ 2", ratio <= 2.0)
    if a is not None:
        add("ATE / all_segments' ATE", _ratio(s["ate_rmse"], a["ate_rmse"]), "< 1", s["ate_rmse"] < a["ate_rmse"])
        # consistency: how far the mean NEES is from its expected value (3), in either direction, on a log
        # scale (an under-confident and an over-confident filter can both have few frames inside)
        off_s = abs(math.log(s["nees_pose_mean"] / 3.0))
        off_a = abs(math.log(a["nees_pose_mean"] / 3.0))
        add("|log(NEES / 3)|, minus all_segments'", off_s - off_a, "< 0", off_s < off_a)
    return goals


def goals_caveats(summary: dict, frames: int | None = None) -> list[str]:
    """Why the goals of ``summary`` may not be the issue's: fewer than :data:`GOALS_MIN_TRIALS` trials of a
    scenario, or its runs cut short by ``frames`` (``--frames``: a scenario whose runs have that many frames
    was cut, or ended there). Empty when neither holds."""
    notes = []
    few = {scen: min(s["trials"] for s in by.values()) for scen, by in summary.items()}
    few = {k: v for k, v in few.items() if v < GOALS_MIN_TRIALS}
    if few:
        notes.append(f"the goals are stated for N ≥ {GOALS_MIN_TRIALS} trials; this evaluation has "
                     + ", ".join(f"{k} N = {v}" for k, v in few.items())
                     + " (the bounds are N's, but a few trials decide little)")
    cut = [scen for scen, by in summary.items()
           if frames is not None and max(s["frames"] for s in by.values()) >= frames]
    if cut:
        notes.append(f"--frames {frames} cut the runs of {', '.join(cut)} short: the goals are stated over every "
                     "frame of each scenario")
    return notes


# ------------------------------------------------------------------ report
REPORT_COLUMNS = (
    ("nees_pose_mean", "pose NEES", "{:.2f}"), ("nees_pose_fraction_inside", "frames inside", "{:.0%}"),
    ("nees_pose_fraction_above", "frames above", "{:.0%}"),
    ("nees_landmark_mean", "landmark NEES", "{:.2f}"), ("nis_mean", "NIS", "{:.2f}"),
    ("ate_rmse", "ATE [m]", "{:.3f}"), ("ate_ratio_dead_reckoning", "ATE / DR", "{:.2f}"),
    ("landmark_error_mean", "landmark error [m]", "{:.3f}"), ("landmarks_mean", "landmarks", "{:.1f}"),
    ("selection_precision", "precision", "{:.2f}"), ("selection_recall", "recall", "{:.2f}"),
    ("reobservation_selected", "re-obs. selected", "{:.0%}"), ("reobservation_rejected", "re-obs. rejected", "{:.0%}"),
    ("time_per_frame", "s / frame", "{:.2f}"),
)
"""Columns of the printed table and the report: (summary key, heading, format)."""


def format_value(value, fmt: str) -> str:
    """``fmt`` applied to a number; NaN / None as ``—``."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "—"
    return fmt.format(value)


def report_markdown(summary: dict, goals: Sequence[Goal], figures: dict[str, str], meta: dict,
                    failed: Sequence[dict] = (), caveats: Sequence[str] = ()) -> str:
    """The Markdown report: settings, the failed tasks, one table per scenario, the goals, the figures, the
    definitions.

    ``figures``: ``{name: relative path}``; ``meta``: settings to list (trials, jobs, backend, seed, …);
    ``failed``: the tasks that failed (:func:`failures`), listed with their messages and left out of the tables;
    ``caveats``: notes printed above the goals (:func:`goals_caveats`).
    """
    lines = ["# stablemarks evaluation", ""]
    lines += [f"- {k}: {v}" for k, v in meta.items()]
    if failed:
        lines += ["", "## Failed tasks", "",
                  f"{len(failed)} task(s) failed; they are left out of the tables below (the other trials went on).",
                  "", "| scenario | trial | seed | method | error |", "|---|---:|---:|---|---|"]
        for r in failed:
            message = str(r["error"]).replace("|", "\\|")
            lines.append(f"| {r['scenario']} | {r['trial']} | {r['seed']} | {r['method']} | {message} |")
    for scen, by_method in summary.items():
        first = next(iter(by_method.values()))
        lines += ["", f"## {scen}", "",
                  f"{first['trials']} trials of {first['frames']} frames. Pose NEES bounds (3 dof, N = "
                  f"{first['trials']}): [{first['nees_pose_bounds'][0]:.2f}, {first['nees_pose_bounds'][1]:.2f}].", ""]
        lines.append("| method | " + " | ".join(h for _, h, _ in REPORT_COLUMNS) + " |")
        lines.append("|---|" + "---:|" * len(REPORT_COLUMNS))
        for method, s in by_method.items():
            lines.append(f"| {method} | " + " | ".join(format_value(s[k], f) for k, _, f in REPORT_COLUMNS) + " |")
        lines.append("")
        for method, s in by_method.items():
            for key, label in (("nees_landmark", "landmark NEES"), ("nis", "NIS")):
                if s[f"{key}_count"]:
                    lo, hi = s[f"{key}_bounds"]
                    lines.append(f"- {method}: {label} {s[f'{key}_mean']:.2f} over {s[f'{key}_count']} values, "
                                 f"bounds [{lo:.2f}, {hi:.2f}]")
    if goals:
        lines += ["", "## Goals of the full method", "", "| scenario | goal | value | target | met |",
                  "|---|---|---:|---|---|"]
        for g in goals:
            met = "n/a" if g.met is None else ("yes" if g.met else "**no**")
            lines.append(f"| {g.scenario} | {g.name} | {g.value} | {g.target} | {met} |")
        if caveats:
            lines += [""] + [f"Note: {c}." for c in caveats]
    if figures:
        lines += ["", "## Figures", ""]
        lines += [f"![{name}]({path})" for name, path in figures.items()]
    doc = (__doc__ or "").split("Metrics (per scenario and method;", 1)
    if len(doc) == 2:
        lines += ["", "## Definitions", "", "Metrics (per scenario and method;" + doc[1].rstrip()]
    return "\n".join(lines) + "\n"
