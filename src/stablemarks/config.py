"""All thresholds in one configuration object, with their defaults, loadable from YAML.

A configuration file holds any subset of the sections below; everything left out keeps its default. The
defaults of the main settings (every key, with its unit, is in the field docstrings of each section's class;
the README's "Configuration" block shows more of them)::

    noise:     {sigma_img: 0.25, boundary_px: 1.0, free_boundary_px: 8.0}   # [px]; the paper preset: 0.5, null, null
    odometry:  {trans_per_m: 0.05, rot_per_m_deg: 2.0, rot_per_rad: 0.05, trans_per_rad: 0.005}
    pan:       {policy: free_edges, angle: 0.0, max_rate: 1.0471975511965976}   # rad, rad/s
    segments:  {gradient_threshold: 40, min_length: 16}                       # Sobel units, px
    matching:  {min_similarity: 0.5, min_overlap: 0.5}
    sad:       {block_size: 15, num_disparities: 64, min_disparity: 0, lr_tolerance: 1.0}   # px
    filter:    {tolerance: 1.0, min_support: 0.5}
    planes:    {gate_sigma: 3.0, min_pixels: 300, disparity_bias_px: 0.0, fit_covariance: clustered}
    landmarks: {boundary_sigma: 3.0, min_length_similarity: 0.7, min_contrast: 30, max_range: 12.0,
                max_incidence_deg: 60.0, boundary_gate_sigma: 3.0}           # m, deg
    ekf:       {max_updates_per_frame: 6, edge_updates: false, wall_updates: false, tie_blind_entries: false}
    health:    {blind_frames: 10, drift_sigma: 4.0}

The noise values are measured (``stablemarks calibrate-noise``), not the paper's; ``Config.preset("paper")``
(``--preset paper``) holds the paper's (:data:`PRESETS`). A command resolves its configuration as the preset,
then a ``--config`` file, then ``--set`` (``commands._common.load_run_config``).

Unknown sections or keys are rejected with a message naming them.

One home for each physical parameter: the line-column noise ``noise.sigma_img`` is read by the plane
prediction and fit, the boundary search, the feature model and the filter (the camera handed to them
carries it: :meth:`Config.camera`); the SAD window ``sad.block_size`` and the disparity range
``sad.min_disparity``/``sad.num_disparities`` are read by the segment matcher, the disparity filter, the
plane fit and the boundary model; the odometry noise model ``odometry`` by the filter's prediction. The
settings derived from them (:data:`DERIVED`) cannot be set on their own.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

from .errors import ConfigError, InputError, expected
from .estimation import EKFConfig
from .geometry import StereoCamera
from .health import HealthConfig
from .landmarks import LandmarkConfig
from .maps import read_yaml
from .motion import OdometryNoise
from .planes import PlaneConfig
from .viewing import PanConfig
from .vision.area_stereo import SADConfig
from .vision.segment_stereo import MatchConfig
from .vision.segments import SegmentConfig


@dataclass(frozen=True)
class FilterConfig:
    """Dropping segment pairs whose disparity disagrees with the disparity image (Fig 5 → Fig 6)."""

    tolerance: float = 1.0
    """Largest |pair disparity − disparity image| that still agrees [px]."""
    min_support: float = 0.5
    """Fraction of the segment's edge pixels that must agree."""
    search_radius: int = 7
    """Columns either side of the segment searched for an agreeing disparity [px]: half the SAD window
    (derived from ``sad.block_size``), because an edge at a depth discontinuity takes its disparity from
    whichever side the window matched (a low-texture plane, like a whiteboard, is matched only some pixels
    in from its edge)."""


@dataclass(frozen=True)
class NoiseConfig:
    """Measurement noise shared by every stage that models uncertainty."""

    sigma_img: float = 0.25
    """Standard deviation of a vertical line's column in one image, as the filter must take it [px]. Used by the
    plane prediction gates and fit (Eqs 4–10), the boundary and feature model (Eqs 12–17) and the filter's
    observation noise (Eq 20). Measured, not the paper's 0.5 px (the ``paper`` preset): on the simulator's
    realistic optics a matched line is only 0.03–0.13 px RMS from its true column, but the errors of the lines of
    one frame and of one line over frames are not independent, and a filter taking them as independent at that
    level is overconfident (room's pose NEES 16 with 0.1 px). ``stablemarks calibrate-noise`` measures the
    line noise and then the smallest multiple of it with which the filter is consistent on recordings with
    ground truth: 0.25 px here (pose NEES 3.7 on room, 3.9 on corridor, 2.0 on office). With the association and
    pan rules of December 2026, 0.15 px was tried (``stablemarks eval``, 8–10 trials): lab 1.3 → 2.0 and hall
    2.1 → 3.1, but room 2.6 → 7.1 and office overconfident over its first 40 frames (NEES 5–11); not adopted.
    The lines themselves scatter by only 0.014–0.034 px about their landmark's mean error (0.01–0.07 px) on the
    simulator; 0.05 px with a wall's shared disparity error modelled (``planes.disparity_bias_px`` 0.044) and the
    SAD pixel noise set apart (``planes.disparity_noise_px`` 0.2) halved the pose error again and was consistent
    on room, but narrowed the gates of the plane prediction so far that a kidnapped or wrongly panned robot's
    walls were no longer fitted whole (the room kidnapped by 0.5 m was not relocalized; a wrong pan was not
    recognised): not adopted yet."""

    boundary_px: float | None = 1.0
    """σ of a boundary's column when a member segment marks the edge (Sec 3.2: the boundary moved to the
    outermost segment) [px], shared by both images, beyond the line noise of that segment pair (the spread of
    the region's border rows it replaced no longer applies). None: a uniform allowance over the SAD window,
    ``sad.block_size / sqrt(12)`` (4.3 px for 15 px; the paper's model, which reproduces Table 1's σ). Measured
    at the true pose (3 trials × 60–80 frames of lab, room, corridor, office, hall): snapped boundaries are
    0.07–0.22 px RMS from the edge and 99 % lie within 0.4 px, but a few snap onto a line 2–8 px inside the edge
    (a whiteboard's frame, the hall's screens at 9 m), which no Gaussian σ covers: the map checks boundaries
    before (``landmarks.boundary_gate_sigma``), against each other (both ends of a wall, two walls' ends:
    ``landmarks.boundaries_apart``) and after the frame's update (``Localizer._recheck_boundaries``).
    1 px since December 2026, together with ``planes.fit_covariance`` ``clustered`` (5 trials each of lab,
    room, corridor, office, hall and ``benchmarks/scenarios/storeroom.yaml``, against 2 px with the independent
    fit covariance): ATE 0.61–0.93 of the former on five of them (office 1.09), the storeroom's pose NEES 8.1 → 3.5
    (frames inside its 95 % bounds 0.67 → 0.90) and its landmark NEES 3.3 → 0.6, but lab, corridor and hall more
    cautious (pose NEES 1.2–1.5, see ``docs/uncertainty.md``). 0.5 px with the clustered fit was tried on the same
    trials: lab 0.71 and the storeroom 0.96 of frames inside, but office 0.60, and the corridor without its pan
    column 1.09 times dead reckoning's ATE (1 px: 0.90). The 2 px before covered the snaps above when they were
    modelled, and the fitted wall's too small covariance, which turned into a scale error along a wall seen at a
    slant.
    0.25 px, with ``ekf.edge_updates``, takes the ATE down 1.7–3 times on lab, room and corridor but is not
    the default yet (see ``ekf.edge_updates``).
    Before those cross-checks and the clustered fit covariance, 0.5 px was tried (8 trials): frames with the pose
    NEES inside its 95 % bounds 0.10 → 0.76 on lab, 0.96 → 0.92 room, 0.44 → 0.48 corridor, 0.80 → 0.60 office,
    0.64 → 0.97 hall, loop's NEES 0.79 (the defaults not rerun there); but selection precision fell on hall
    (0.99 → 0.93) and on the storeroom (0.75 → 0.69), whose landmark NEES rose 2.3 → 9.3 (on the hall, a line a few
    px inside a screen's edge was no longer kept away from the boundary by its σ; the storeroom's losses were
    traced since to a wrong end kept by the map and a free edge 0.58 m off let through, which the cross-checks now
    refuse): not adopted then. With
    the line noise, this σ and the wall's shared disparity error at their measured values (``sigma_img`` 0.08,
    ``boundary_px`` 0.1, ``planes.disparity_bias_px`` 0.04) the ATE fell to 0.5–0.9 of the defaults' on the five
    built-in scenarios, but lab and room were too cautious (pose NEES 0.8–1.3). With these and with the defaults
    alike, the two pose directions the walls observe well are held 4–10 times less certain (in variance) than their
    errors, while the direction they hardly observe (along the wall against the heading) is not
    (``benchmarks/pose_directions.py``).
    Earlier measurements: 0.75 px was tried on all six scenarios: pose NEES closer to its bounds on lab
    (1.3 → 1.5) and room (2.4 → 2.8), but one office trial's recovery after a blind stretch then failed (ATE
    0.22 m)."""
    free_boundary_px: float | None = 8.0
    """The same when no segment marks the edge and the boundary is the planar region's border itself: block
    matching moves a depth edge by about half its window, mostly inward (``calibrate-noise``: 7.4 px on the
    office, 11.8 px on the lab with 15 px windows; RMS 40–60 mm at 4 m). None: ``sad.block_size / sqrt(12)``."""

    def __post_init__(self) -> None:
        v = self.sigma_img
        if isinstance(v, bool) or not isinstance(v, int | float) or not (v == v and 0 < v < 1e3):
            raise ConfigError(expected("a positive number of pixels below 1000", v, where="noise.sigma_img"))
        for name in ("boundary_px", "free_boundary_px"):
            v = getattr(self, name)
            bad = isinstance(v, bool) or not isinstance(v, int | float) or not (v == v and 0 <= v < 1e3)
            if v is not None and bad:
                raise ConfigError(expected("null or a number of pixels in [0, 1000)", v, where=f"noise.{name}"))


DERIVED = {
    ("matching", "min_disparity"): "sad.min_disparity",
    ("matching", "max_disparity"): "sad.min_disparity + sad.num_disparities",
    ("filter", "search_radius"): "sad.block_size // 2",
    ("planes", "correlation_px"): "sad.block_size",
}
"""Settings that follow another one (one home for each physical parameter): ``(section, key)`` → its rule."""


@dataclass(frozen=True)
class Config:
    """Every setting of the method, grouped by section (frozen; change it with :meth:`with_overrides`).

    Sections: ``noise`` (line-column and boundary noise [px]), ``odometry`` (wheel-odometry noise per metre
    and per radian), ``pan`` (where the head looks [rad, rad/s]), ``segments``, ``matching``, ``sad``
    (block size and disparity range [px]), ``filter``, ``planes``, ``landmarks`` (selection and entry limits
    [m, deg]), ``ekf`` and ``health``. Units are in each section's field docstrings. ``Config.preset("paper")``
    gives the paper's noise values. The settings of :data:`DERIVED` are set from their home in
    ``__post_init__``: a ``Config`` built with another value for them gets the derived one.
    """

    noise: NoiseConfig = field(default_factory=NoiseConfig)
    odometry: OdometryNoise = field(default_factory=OdometryNoise)
    pan: PanConfig = field(default_factory=PanConfig)
    segments: SegmentConfig = field(default_factory=SegmentConfig)
    matching: MatchConfig = field(default_factory=MatchConfig)
    sad: SADConfig = field(default_factory=SADConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    planes: PlaneConfig = field(default_factory=PlaneConfig)
    landmarks: LandmarkConfig = field(default_factory=LandmarkConfig)
    ekf: EKFConfig = field(default_factory=EKFConfig)
    health: HealthConfig = field(default_factory=HealthConfig)

    def __post_init__(self) -> None:
        sad = self.sad
        derived = {
            "matching": replace(self.matching, min_disparity=float(sad.min_disparity),
                                max_disparity=float(sad.min_disparity + sad.num_disparities)),
            "filter": replace(self.filter, search_radius=int(sad.block_size) // 2),
            "planes": replace(self.planes, correlation_px=float(sad.block_size)),
        }
        for name, value in derived.items():
            if value != getattr(self, name):
                object.__setattr__(self, name, value)

    @classmethod
    def preset(cls, name: str) -> Config:
        """A named preset (:data:`PRESETS`): ``paper`` holds the paper's noise values (σ_img = 0.5 px, the
        boundary's SAD-window allowance), with which Table 1 is reproduced."""
        if name not in PRESETS:
            raise ConfigError(expected(f"one of {', '.join(PRESETS)}", name, where="preset"))
        return parse_config(PRESETS[name], f"preset {name}")

    def camera(self, camera: StereoCamera) -> StereoCamera:
        """``camera`` with this configuration's line-column noise ``noise.sigma_img`` (the one home of σ_img:
        every stage reads it from the camera it is handed)."""
        if camera.sigma_img == self.noise.sigma_img:
            return camera
        return replace(camera, sigma_img=float(self.noise.sigma_img))

    def with_source_defaults(self, defaults: dict) -> Config:
        """A copy in which the settings a source describes (``{section: {key: value}}``, e.g. a simulated
        robot's odometry noise and pan policy, or a recording's odometry noise) replace those this
        configuration leaves at their default; settings chosen otherwise stay."""
        if not defaults:
            return self
        base = Config()
        keep = {}
        for section, values in defaults.items():
            for key, value in values.items():
                if getattr(getattr(self, section), key) == getattr(getattr(base, section), key):
                    keep.setdefault(section, {})[key] = value
        return parse_config(keep, "source defaults", base=self) if keep else self

    def to_dict(self) -> dict:
        """Plain ``{section: {key: value}}`` of every settable key (derived ones left out), loadable again."""
        def plain(v):
            return list(v) if isinstance(v, tuple) else v

        return {f.name: {k: plain(v) for k, v in dataclasses.asdict(getattr(self, f.name)).items()
                         if (f.name, k) not in DERIVED} for f in fields(self)}

    def with_overrides(self, overrides: dict, source: str = "config") -> Config:
        """A copy with ``{section: {key: value}}`` applied, validated like a file."""
        return parse_config(overrides, source, base=self)


PRESETS = {
    "paper": {"noise": {"sigma_img": 0.5, "boundary_px": None, "free_boundary_px": None},
              "ekf": {"edge_updates": False}, "landmarks": {"off_wall_min_lines": 0},
              "planes": {"fit_covariance": "independent"}},
    "narrow": {"noise": {"sigma_img": 0.06, "boundary_px": 0.06},
               "planes": {"disparity_noise_px": 0.354},
               "ekf": {"landmark_sigma_floor": 0.0, "landmark_sigma_floor_per_m": 0.0002, "inflation_p": 0.001,
                       "widen_blind_entries": True},
               "landmarks": {"min_line_gap_px": 4.0}},
}
"""Named configurations: ``paper`` — the paper's σ_img = 0.5 px (Sec 2.3.1), a boundary known to within the
SAD window (``w / sqrt(12)``), which reproduce Table 1's σ, and a filter
that uses a boundary only to model landmarks (no ``ekf.edge_updates``) and tests a line's offset from its wall
with the model's noise alone (``landmarks.off_wall_min_lines`` 0), as the paper's; the defaults are
measured instead (``stablemarks calibrate-noise``). ``narrow`` — line and snapped-boundary noise the size of
the simulator's usual errors (0.06 px), the plane gates as the defaults', a landmark σ floor of 0.2 mm per metre
of range instead of the defaults' 5 mm (a line's error that stays with it is an angle: 0.1 px at f = 500 px;
without it the loop's landmarks, seen a hundred times and more, end held to 0.2 mm with errors of 1–3 mm), the
variance the frame's innovations show missing added (``ekf.inflation_p``), landmarks entered blind as uncertain
along their wall as the pose, and no line entered within 4 px of another: nearer to consistent on clean scenes
than the defaults, overconfident on some frames of cluttered ones (``docs/uncertainty.md``, "The narrow
preset")."""


MAX_SETTING = 1e9
"""Largest magnitude of a numeric setting: no threshold, count or σ of the pipeline comes near it, and below
it every setting converts to a float or an int64 exactly enough."""


def parse_config(data: object, source: str = "config", base: Config | None = None) -> Config:
    """Validate a configuration document (see the module docstring)."""
    base = base or Config()
    if data is None:
        return base
    if not isinstance(data, dict):
        raise ConfigError(expected("a mapping of sections", type(data).__name__, where=source))
    sections = {f.name for f in fields(Config)}
    updates = {}
    for name, values in data.items():
        if name not in sections:
            raise ConfigError(f"{source}: unknown section {name!r} (known: {', '.join(sorted(sections))})")
        current = getattr(base, name)
        if not isinstance(values, dict):
            raise ConfigError(expected("a mapping of settings", values, where=f"{source}: {name}"))
        known = {f.name: f for f in fields(current)}
        clean = {}
        for key, value in values.items():
            if (name, key) in DERIVED:
                raise ConfigError(f"{source}: {name}.{key}: set from {DERIVED[name, key]} (one home for each "
                                  "physical parameter); set that instead")
            if key not in known:
                settable = sorted(k for k in known if (name, k) not in DERIVED)
                raise ConfigError(f"{source}: {name}.{key}: unknown setting (known: {', '.join(settable)})")
            default = getattr(current, key)
            if value is None and "None" in str(known[key].type):
                clean[key] = None  # an optional setting switched to its model (e.g. noise.boundary_px)
                continue
            if isinstance(default, bool) and not isinstance(value, bool):
                raise ConfigError(expected("true or false", value, where=f"{source}: {name}.{key}"))
            if isinstance(default, int | float) and not isinstance(default, bool):
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise ConfigError(expected("a number", value, where=f"{source}: {name}.{key}"))
                try:
                    finite = math.isfinite(value)
                except OverflowError:  # an integer beyond the float range
                    finite = False
                if not finite:
                    raise ConfigError(expected("a finite number", value, where=f"{source}: {name}.{key}"))
                if abs(value) > MAX_SETTING:
                    raise ConfigError(expected(f"a number within ±{MAX_SETTING:g}", value,
                                               where=f"{source}: {name}.{key}"))
                if isinstance(default, int) and not isinstance(default, bool) and float(value) != int(value):
                    raise ConfigError(expected("a whole number", value, where=f"{source}: {name}.{key}"))
                value = type(default)(value)
            clean[key] = value
        try:
            updates[name] = replace(current, **clean)
        except InputError as exc:
            raise ConfigError(f"{source}: {name}: {exc}") from None
        except (TypeError, ValueError, ArithmeticError) as exc:  # ArithmeticError: a number out of range
            raise ConfigError(f"{source}: {name}: {exc}") from None
    return replace(base, **updates)


def load_config(path: str | Path | None) -> Config:
    """Load a configuration file; ``None`` gives the defaults."""
    if path is None:
        return Config()
    return parse_config(read_yaml(path, "configuration file"), str(path))
