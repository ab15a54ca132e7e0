"""Scenario files of the simulator: the world, the camera, the lighting and the robot's path.

A scenario is a YAML file in metres and radians, or degrees where the key ends in ``_deg``. Every field is
validated; a mistake becomes one :class:`~stablemarks.errors.ConfigError` line naming the file and the
field, e.g. ``lab.yaml: walls[1].texture.scale: expected a positive number, got -2``. Unknown keys are
rejected. Built-in scenarios live in ``sim/scenarios/`` and load by name (``load_scenario("lab")``).

Format (defaults in parentheses)::

    name: lab                       # (the file's stem)
    seed: 1                         # default seed of a simulated run: odometry, exposure, sensor noise (0)
    camera:                         # geometry.StereoCamera fields (its defaults), plus:
      width: 640                    # [px]
      height: 480
      f: 500.0                      # [px]
      cu: 319.5                     # principal point [px]
      cv: 239.5
      baseline: 0.12                # [m]
      mount_x: 0.0                  # left optical centre (pan axis) in the robot frame [m]
      mount_y: 0.0
      mount_height: 1.0             # [m]
      image_noise: 2.0              # σ of the signal-independent (read) sensor noise [gray levels] (2.0)
      pan_limits_deg: [-60, 60]     # mechanical pan range ([-90, 90])
    room:                           # optional
      floor: {kind: noise, base: 90, contrast: 12, scale: 0.08}       # texture in world (x, y)
      ceiling_height: 2.8           # [m]; null = no ceiling (null)
      ceiling: {kind: plain, base: 200}
      background: 40                # gray level where a ray hits nothing (40)
    lighting:                       # optional
      ambient: 0.7                  # fraction of the albedo lit by ambient light (0.7)
      light_position: [0, 0, 2.5]   # a point light [m] ([0, 0, 2.5])
      light_intensity: 0.3          # diffuse fraction at normal incidence (0.3)
      shininess: 30                 # Blinn-Phong exponent of glossy highlights (30)
      exposure_sigma: 0.03          # σ of the per-frame log exposure gain (0.0)
    optics:                         # optional; the defaults model a real camera, all zeros the ideal one
      blur_sigma: 0.5               # σ of the lens's Gaussian point spread function [px] (0.5)
      vignetting: 0.25              # light lost in the image corners, cos⁴-like radial falloff, 0–0.9 (0.25)
      motion_blur: 1.0              # longest horizontal motion blur [px]; each frame draws its length
                                    # uniformly in [0, motion_blur] (1.0)
      gain_sigma: 0.04              # σ of the per-frame log analog gain (0.04)
      shot_noise: 2.0               # σ of photon shot noise at gray level 255 and unit gain [gray levels];
                                    # at gray level I it is shot_noise·sqrt(I/255) (2.0)
    walls:                          # vertical planes standing on the floor segment p1 → p2
      - id: partition               # letters, digits, '_' or '-'; unique among walls, boxes and poles
        name: partition             # (the id)
        p1: [0.0, 4.0]              # [m]
        p2: [1.2, 4.0]
        z: [0.0, 1.8]               # bottom and top [m] ([0, 2.5])
        in_map: true                # in the robot's map (true); false = in the world only
        reference: true             # in the map as a reference plane (true) or as an occluder only (false)
        free_edges: [p1]            # map: which ends are free boundaries ([])
        visible_from: both          # map: both | left | right of p1 → p2 (both)
        texture: {kind: noise, base: 110, contrast: 14, scale: 0.03}
        gloss: 0.0                  # specular highlight strength 0–1 (0)
    features:                       # vertical features painted on walls
      - id: partition-2             # (<wall>-f<index>)
        wall: partition
        s: 0.1094                   # distance along the wall from p1 [m]
        z: [0.8, 1.287]             # bottom and top [m], inside the wall's z
        kind: edge                  # edge: a step at s fading back over `fade` towards +s (one image edge)
                                    # bar: a strip of `width` from s to s + width (two image edges)
        contrast: 60                # signed step in gray levels of the albedo
        fade: 0.1                   # edge only [m] (0.1)
        width: 0.05                 # bar only [m], required
    clutter:                        # in no map
      boxes:
        - {id: crate, center: [1.0, 2.0], size: [0.6, 0.4], yaw_deg: 10, height: 0.8, texture: {...}}
      poles:
        - {id: lamp, center: [-1.0, 3.0], radius: 0.05, height: 2.0, texture: {...}}
    robot:
      start: {x: 0.0, y: 0.0, theta_deg: 90}
      path:                         # steps in order, each one of
        - forward: 2.0              #   drive straight [m] (> 0)
        - turn_deg: 30              #   turn on the spot [deg] (positive to the left)
        - to: [1.0, 3.0]            #   turn towards a world point, then drive to it [m]
      frame_spacing: 0.1            # a stereo frame every ... metres driven (0.1)
      frame_turn_deg: 10            # ... and every ... degrees turned (10)
      odometry: {trans_per_m: 0.05, rot_per_m_deg: 2.0, rot_per_rad: 0.05, trans_per_rad: 0.005}
      pan:
        policy: look_at_free_edges  # fixed | look_at_free_edges (fixed)
        angle_deg: 0.0              # the fixed pan, or the first pan while no free edge is in sight (0)

A texture is ``{kind: noise | plain, base: 0–255, contrast: σ in gray levels, scale: blob size [m]}``
(defaults: noise, 128, 10, 0.03); ``plain`` ignores ``contrast`` and ``scale``.

``camera.image_noise`` is the signal-independent (read) noise; with ``optics.shot_noise`` the noise of a
pixel of mean gray level ``I`` (before the analog gain ``g``) is ``g·sqrt(image_noise² + shot_noise²·I/255)``.
With ``optics: {blur_sigma: 0, vignetting: 0, motion_blur: 0, gain_sigma: 0, shot_noise: 0}`` the renderer
makes exactly the images of the ideal camera (exposure jitter and constant Gaussian noise only).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError, expected
from ..geometry import SE2, StereoCamera, wrap_angle
from ..maps import COORDINATE_LIMIT, Map, ReferencePlane, parse_plane, read_yaml
from ..motion import Forward, GoTo, OdometryNoise, PathStep, Turn

SCENARIO_DIR = Path(__file__).parent / "scenarios"
_ID = re.compile(r"^[A-Za-z0-9_\-]+$")
_REQUIRED = object()

MAX_IMAGE_SIDE = 4096
"""Largest width and height of a scenario's camera [px] (a 4096×4096 stereo pair renders in about 10 s)."""

MAX_FRAMES = 100_000
"""Most stereo frames a scenario's path may generate (``robot.path`` cut by ``frame_spacing`` and
``frame_turn_deg``)."""


# --------------------------------------------------------------- the model
@dataclass(frozen=True)
class Texture:
    """Procedural albedo: ``base`` gray level plus band-limited noise of std ``contrast``, blobs of ``scale`` [m]."""

    kind: str = "noise"
    base: float = 128.0
    contrast: float = 10.0
    scale: float = 0.03


@dataclass(frozen=True)
class Wall:
    """A vertical plane on the floor segment ``p1 → p2`` [m], from ``z[0]`` to ``z[1]`` [m] high."""

    id: str
    p1: tuple[float, float]
    p2: tuple[float, float]
    z: tuple[float, float] = (0.0, 2.5)
    name: str = ""
    in_map: bool = True
    reference: bool = True
    free_edges: tuple[str, ...] = ()
    visible_from: str = "both"
    texture: Texture = Texture()
    gloss: float = 0.0

    @property
    def plane(self) -> ReferencePlane:
        """The wall as a map plane (its geometry and map attributes)."""
        return ReferencePlane(self.id, self.p1, self.p2, self.name or self.id, self.free_edges, self.z,
                              self.visible_from, self.reference)


@dataclass(frozen=True)
class Feature:
    """A vertical feature painted on a wall: an ``edge`` (one image edge) or a ``bar`` (two)."""

    id: str
    wall: str
    s: float
    z: tuple[float, float]
    kind: str = "edge"
    contrast: float = 60.0
    fade: float = 0.1
    width: float = 0.0

    def edges(self) -> tuple[tuple[str, float, float], ...]:
        """The feature's image edges: ``(edge id, s [m], signed albedo step along +s [gray])``."""
        if self.kind == "edge":
            return ((self.id, self.s, self.contrast),)
        return ((f"{self.id}-a", self.s, self.contrast), (f"{self.id}-b", self.s + self.width, -self.contrast))


@dataclass(frozen=True)
class Box:
    """A free-standing box (clutter): footprint ``size`` (sx, sy) [m] about ``center``, rotated by ``yaw`` [rad]."""

    id: str
    center: tuple[float, float]
    size: tuple[float, float]
    height: float
    yaw: float = 0.0
    texture: Texture = Texture()

    def corners(self) -> np.ndarray:
        """``(4, 2)`` footprint corners [m], counter-clockwise."""
        hx, hy = 0.5 * self.size[0], 0.5 * self.size[1]
        local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        return SE2(self.center[0], self.center[1], self.yaw).transform(local)


@dataclass(frozen=True)
class Pole:
    """A free-standing vertical cylinder (clutter) of ``radius`` [m] and ``height`` [m]."""

    id: str
    center: tuple[float, float]
    radius: float
    height: float
    texture: Texture = Texture()


@dataclass(frozen=True)
class Lighting:
    """Ambient plus one point light with Blinn-Phong highlights, and the per-frame exposure jitter."""

    ambient: float = 0.7
    light_position: tuple[float, float, float] = (0.0, 0.0, 2.5)
    light_intensity: float = 0.3
    shininess: float = 30.0
    exposure_sigma: float = 0.0


@dataclass(frozen=True)
class Optics:
    """The camera's imperfections beyond the pinhole: lens blur, vignetting, motion blur, gain, shot noise.

    ``blur_sigma`` [px]: σ of the Gaussian point spread function; ``vignetting``: fraction of the light lost
    in the farthest image corner (a cos⁴-like radial falloff); ``motion_blur`` [px]: the longest horizontal
    box kernel (each frame draws its length uniformly in ``[0, motion_blur]``); ``gain_sigma``: σ of the
    per-frame log analog gain; ``shot_noise`` [gray levels]: σ of the photon shot noise at gray level 255.
    """

    blur_sigma: float = 0.5
    vignetting: float = 0.25
    motion_blur: float = 1.0
    gain_sigma: float = 0.04
    shot_noise: float = 2.0

    @classmethod
    def ideal(cls) -> Optics:
        """No optics at all: the renderer's images are those of a pinhole camera with constant noise."""
        return cls(0.0, 0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class Room:
    """Floor, optional ceiling, and the gray level of rays that hit nothing."""

    floor: Texture = Texture("noise", 90.0, 12.0, 0.08)
    ceiling_height: float | None = None
    ceiling: Texture = Texture("plain", 200.0, 0.0, 0.1)
    background: float = 40.0


@dataclass(frozen=True)
class PanPolicy:
    """How the head pans: ``fixed`` at ``angle`` [rad], or ``look_at_free_edges`` (starting at ``angle``)."""

    policy: str = "fixed"
    angle: float = 0.0


@dataclass(frozen=True)
class RobotPlan:
    """Start pose, path, frame spacing, odometry noise and pan policy of a simulated run."""

    start: SE2 = SE2()
    path: tuple[PathStep, ...] = ()
    frame_spacing: float = 0.1
    frame_turn: float = math.radians(10.0)
    odometry: OdometryNoise = OdometryNoise()
    pan: PanPolicy = PanPolicy()


@dataclass(frozen=True)
class Scenario:
    """A validated scenario (format in the module docstring); ``map`` is the robot's map of it."""

    name: str
    camera: StereoCamera
    walls: tuple[Wall, ...]
    seed: int = 0
    image_noise: float = 2.0
    pan_limits: tuple[float, float] = (-math.pi / 2, math.pi / 2)
    features: tuple[Feature, ...] = ()
    boxes: tuple[Box, ...] = ()
    poles: tuple[Pole, ...] = ()
    lighting: Lighting = Lighting()
    optics: Optics = Optics()
    room: Room = Room()
    robot: RobotPlan = RobotPlan()
    source: str = field(default="", compare=False)

    @property
    def map(self) -> Map:
        """The walls with ``in_map: true`` as a :class:`~stablemarks.maps.Map`."""
        return Map(tuple(w.plane for w in self.walls if w.in_map), source=f"{self.name} map")

    def wall(self, wall_id: str) -> Wall:
        for w in self.walls:
            if w.id == wall_id:
                return w
        raise KeyError(wall_id)


# --------------------------------------------------------------- loading
def builtin_scenarios() -> list[str]:
    """Names of the scenarios shipped with the package."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a built-in scenario by name (``"lab"``) or a scenario file by path, and validate it."""
    text = str(name_or_path)
    builtin = SCENARIO_DIR / f"{text}.yaml"
    # a file of that name in the working directory wins; a folder of that name (a run's output) does not
    if _ID.match(text) and builtin.is_file() and not Path(text).is_file():
        return parse_scenario(read_yaml(builtin, "scenario file"), builtin.name, default_name=text)
    path = Path(name_or_path)
    if not path.exists() and path.suffix == "":
        raise ConfigError(expected(f"a scenario file or a built-in name ({', '.join(builtin_scenarios())})",
                                   text, where="scenario"))
    return parse_scenario(read_yaml(path, "scenario file"), str(path), default_name=path.stem)


def _finite(v: int | float) -> bool:
    """Whether a number is finite (an integer too large for a float is not)."""
    try:
        return math.isfinite(v)
    except OverflowError:
        return False


class _Node:
    """A mapping of a scenario file being read: typed getters whose errors name the file and field path."""

    def __init__(self, data: object, source: str, path: str, known: tuple[str, ...], what: str = "a mapping"):
        self.source, self.path = source, path
        if data is None:
            data = {}
        if not isinstance(data, dict):
            raise ConfigError(expected(what, data, where=self.where()))
        unknown = sorted(str(k) for k in set(data) - set(known))
        if unknown:
            raise ConfigError(f"{self.where(unknown[0])}: unknown field (known: {', '.join(known)})")
        self.data = data

    def where(self, key: str | None = None) -> str:
        inner = ".".join(p for p in (self.path, key) if p)
        return f"{self.source}: {inner}" if inner else self.source

    def raw(self, key: str, default=_REQUIRED):
        if key in self.data and self.data[key] is not None:
            return self.data[key]
        if default is _REQUIRED:
            raise ConfigError(f"{self.where(key)}: missing field")
        return default

    def number(self, key: str, default=_REQUIRED, *, lo: float | None = None, hi: float | None = None,
               positive: bool = False) -> float:
        v = self.raw(key, default)
        ok = not isinstance(v, bool) and isinstance(v, int | float) and _finite(v)
        if ok and abs(v) > COORDINATE_LIMIT:
            raise ConfigError(expected(f"a number within ±{COORDINATE_LIMIT:g}", v, where=self.where(key)))
        if positive:
            what = "a positive number"
            ok = ok and v > 0
        elif lo is not None and hi is not None:
            what = f"a number in [{lo:g}, {hi:g}]"
            ok = ok and lo <= v <= hi
        elif lo is not None:
            what = "a non-negative number" if lo == 0 else f"a number >= {lo:g}"
            ok = ok and v >= lo
        else:
            what = "a finite number"
        if not ok:
            raise ConfigError(expected(what, v, where=self.where(key)))
        return float(v)

    def integer(self, key: str, default=_REQUIRED, *, lo: int = 0, hi: int | None = None) -> int:
        v = self.raw(key, default)
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise ConfigError(expected(f"an integer >= {lo}", v, where=self.where(key)))
        if hi is not None and v > hi:
            raise ConfigError(expected(f"an integer <= {hi}", v, where=self.where(key)))
        return int(v)

    def numbers(self, key: str, n: int, default=_REQUIRED, what: str = "") -> tuple[float, ...]:
        v = self.raw(key, default)
        bad = not isinstance(v, list | tuple) or len(v) != n or any(
            isinstance(x, bool) or not isinstance(x, int | float) or not _finite(x) for x in v)
        if bad:
            raise ConfigError(expected(what or f"a list of {n} numbers", v, where=self.where(key)))
        if any(abs(x) > COORDINATE_LIMIT for x in v):
            raise ConfigError(expected(f"numbers within ±{COORDINATE_LIMIT:g}", v, where=self.where(key)))
        return tuple(float(x) for x in v)

    def flag(self, key: str, default=_REQUIRED) -> bool:
        v = self.raw(key, default)
        if not isinstance(v, bool):
            raise ConfigError(expected("true or false", v, where=self.where(key)))
        return v

    def text(self, key: str, default=_REQUIRED, *, choices: tuple[str, ...] | None = None,
             ident: bool = False) -> str:
        v = self.raw(key, default)
        if isinstance(v, int) and not isinstance(v, bool) and ident:
            v = str(v)
        if choices is not None and v not in choices:
            raise ConfigError(expected(f"one of {', '.join(choices)}", v, where=self.where(key)))
        if not isinstance(v, str) or (ident and not _ID.match(v)):
            raise ConfigError(expected("an id of letters, digits, '_' or '-'" if ident else "a string", v,
                                       where=self.where(key)))
        return v

    def child(self, key: str, known: tuple[str, ...]) -> _Node:
        return _Node(self.raw(key, {}), self.source, ".".join(p for p in (self.path, key) if p), known)

    def items(self, key: str, known: tuple[str, ...]) -> list[_Node]:
        v = self.raw(key, [])
        if not isinstance(v, list):
            raise ConfigError(expected("a list", v, where=self.where(key)))
        base = ".".join(p for p in (self.path, key) if p)
        return [_Node(item, self.source, f"{base}[{i}]", known) for i, item in enumerate(v)]


_CAMERA = ("width", "height", "f", "cu", "cv", "baseline", "mount_x", "mount_y", "mount_height",
           "image_noise", "pan_limits_deg")
_TEXTURE = ("kind", "base", "contrast", "scale")
_WALL = ("id", "name", "p1", "p2", "z", "in_map", "reference", "free_edges", "visible_from", "texture", "gloss")
_FEATURE = ("id", "wall", "s", "z", "kind", "contrast", "fade", "width")
_BOX = ("id", "center", "size", "yaw_deg", "height", "texture")
_POLE = ("id", "center", "radius", "height", "texture")
_LIGHTING = ("ambient", "light_position", "light_intensity", "shininess", "exposure_sigma")
_OPTICS = ("blur_sigma", "vignetting", "motion_blur", "gain_sigma", "shot_noise")
_ROOM = ("floor", "ceiling_height", "ceiling", "background")
_ROBOT = ("start", "path", "frame_spacing", "frame_turn_deg", "odometry", "pan")
_TOP = ("name", "seed", "camera", "room", "lighting", "optics", "walls", "features", "clutter", "robot")


def parse_scenario(data: object, source: str = "scenario", *, default_name: str = "scenario") -> Scenario:
    """Validate a scenario document already parsed from YAML (format in the module docstring)."""
    top = _Node(data, source, "", _TOP, "a mapping with camera, walls and robot")
    name = top.text("name", default_name)
    camera, image_noise, pan_limits = _camera(top.child("camera", _CAMERA))
    walls = tuple(_wall(n) for n in top.items("walls", _WALL))
    if not walls:
        raise ConfigError(f"{top.where('walls')}: expected at least one wall")
    clutter = top.child("clutter", ("boxes", "poles"))
    boxes = tuple(_box(n, i) for i, n in enumerate(clutter.items("boxes", _BOX)))
    poles = tuple(_pole(n, i) for i, n in enumerate(clutter.items("poles", _POLE)))
    ids = [w.id for w in walls] + [b.id for b in boxes] + [p.id for p in poles]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise ConfigError(f"{source}: duplicate id {dup[0]!r} among walls and clutter")
    features = tuple(_feature(n, i, walls) for i, n in enumerate(top.items("features", _FEATURE)))
    fids = [f.id for f in features]
    dup = sorted({i for i in fids if fids.count(i) > 1})
    if dup:
        raise ConfigError(f"{top.where('features')}: duplicate id {dup[0]!r}")
    return Scenario(
        name=name,
        seed=top.integer("seed", 0, hi=2**63 - 1),
        camera=camera,
        image_noise=image_noise,
        pan_limits=pan_limits,
        walls=walls,
        features=features,
        boxes=boxes,
        poles=poles,
        lighting=_lighting(top.child("lighting", _LIGHTING)),
        optics=_optics(top.child("optics", _OPTICS)),
        room=_room(top.child("room", _ROOM)),
        robot=_robot(top.child("robot", _ROBOT), pan_limits),
        source=source,
    )


def _camera(n: _Node) -> tuple[StereoCamera, float, tuple[float, float]]:
    d = StereoCamera()
    width = n.integer("width", d.width, lo=1, hi=MAX_IMAGE_SIDE)
    height = n.integer("height", d.height, lo=1, hi=MAX_IMAGE_SIDE)
    camera = StereoCamera(
        width=width, height=height, f=n.number("f", d.f, positive=True),
        cu=n.number("cu", (width - 1) / 2), cv=n.number("cv", (height - 1) / 2),
        baseline=n.number("baseline", d.baseline, positive=True),
        mount_x=n.number("mount_x", d.mount_x), mount_y=n.number("mount_y", d.mount_y),
        mount_height=n.number("mount_height", d.mount_height, positive=True),
    )
    limits = n.numbers("pan_limits_deg", 2, [-90.0, 90.0], "a list [min, max] of degrees")
    if not -180.0 <= limits[0] <= limits[1] <= 180.0:
        raise ConfigError(expected("-180 <= min <= max <= 180", list(limits), where=n.where("pan_limits_deg")))
    return camera, n.number("image_noise", 2.0, lo=0.0), (math.radians(limits[0]), math.radians(limits[1]))


def _texture(n: _Node, default: Texture = Texture()) -> Texture:
    if not n.data:
        return default
    return Texture(
        kind=n.text("kind", default.kind, choices=("noise", "plain")),
        base=n.number("base", default.base, lo=0.0, hi=255.0),
        contrast=n.number("contrast", default.contrast, lo=0.0),
        scale=n.number("scale", default.scale, positive=True),
    )


def _wall(n: _Node) -> Wall:
    plane = parse_plane({k: v for k, v in n.data.items() if k not in ("in_map", "texture", "gloss")}, n.where())
    return Wall(
        id=plane.id, p1=plane.p1, p2=plane.p2, z=plane.z, name=plane.name, in_map=n.flag("in_map", True),
        reference=plane.reference, free_edges=plane.free_edges, visible_from=plane.visible_from,
        texture=_texture(n.child("texture", _TEXTURE)), gloss=n.number("gloss", 0.0, lo=0.0, hi=1.0),
    )


def _feature(n: _Node, index: int, walls: tuple[Wall, ...]) -> Feature:
    ids = [w.id for w in walls]
    wall_id = n.text("wall", ident=True)
    if wall_id not in ids:
        raise ConfigError(expected(f"one of the wall ids {ids}", wall_id, where=n.where("wall")))
    wall = walls[ids.index(wall_id)]
    kind = n.text("kind", "edge", choices=("edge", "bar"))
    length = wall.plane.length
    s = n.number("s", lo=0.0)
    if s > length:
        raise ConfigError(expected(f"a distance along wall {wall_id!r} in [0, {length:.4g}] m", s,
                                   where=n.where("s")))
    z = n.numbers("z", 2, what="a list [bottom, top] in metres")
    if not wall.z[0] <= z[0] < z[1] <= wall.z[1]:
        raise ConfigError(expected(f"bottom < top inside wall {wall_id!r}'s z {list(wall.z)}", list(z),
                                   where=n.where("z")))
    contrast = n.number("contrast")
    if contrast == 0:
        raise ConfigError(expected("a non-zero signed step in gray levels", contrast, where=n.where("contrast")))
    for key, used_by in (("fade", "edge"), ("width", "bar")):
        if key in n.data and kind != used_by:
            raise ConfigError(f"{n.where(key)}: applies to kind {used_by} only, this feature is a {kind}")
    fade = n.number("fade", 0.1, positive=True) if kind == "edge" else 0.1
    width = n.number("width", positive=True) if kind == "bar" else 0.0
    if s + width > length:
        raise ConfigError(expected(f"a bar ending on wall {wall_id!r} (s + width <= {length:.4g} m)", s + width,
                                   where=n.where("width")))
    fid = n.text("id", f"{wall_id}-f{index}", ident=True)
    return Feature(fid, wall_id, s, (z[0], z[1]), kind, contrast, fade, width)


def _box(n: _Node, index: int) -> Box:
    size = n.numbers("size", 2, what="a list [sx, sy] of positive metres")
    if min(size) <= 0:
        raise ConfigError(expected("a list [sx, sy] of positive metres", list(size), where=n.where("size")))
    return Box(
        id=n.text("id", f"box-{index}", ident=True),
        center=n.numbers("center", 2, what="a list of 2 numbers [x, y] in metres"),
        size=size,
        height=n.number("height", positive=True),
        yaw=math.radians(n.number("yaw_deg", 0.0)),
        texture=_texture(n.child("texture", _TEXTURE)),
    )


def _pole(n: _Node, index: int) -> Pole:
    return Pole(
        id=n.text("id", f"pole-{index}", ident=True),
        center=n.numbers("center", 2, what="a list of 2 numbers [x, y] in metres"),
        radius=n.number("radius", positive=True),
        height=n.number("height", positive=True),
        texture=_texture(n.child("texture", _TEXTURE)),
    )


def _lighting(n: _Node) -> Lighting:
    d = Lighting()
    return Lighting(
        ambient=n.number("ambient", d.ambient, lo=0.0),
        light_position=n.numbers("light_position", 3, list(d.light_position),
                                 "a list [x, y, z] in metres"),
        light_intensity=n.number("light_intensity", d.light_intensity, lo=0.0),
        shininess=n.number("shininess", d.shininess, positive=True),
        exposure_sigma=n.number("exposure_sigma", d.exposure_sigma, lo=0.0),
    )


def _optics(n: _Node) -> Optics:
    d = Optics()
    return Optics(
        blur_sigma=n.number("blur_sigma", d.blur_sigma, lo=0.0),
        vignetting=n.number("vignetting", d.vignetting, lo=0.0, hi=0.9),
        motion_blur=n.number("motion_blur", d.motion_blur, lo=0.0),
        gain_sigma=n.number("gain_sigma", d.gain_sigma, lo=0.0),
        shot_noise=n.number("shot_noise", d.shot_noise, lo=0.0),
    )


def _room(n: _Node) -> Room:
    d = Room()
    has_ceiling = n.raw("ceiling_height", None) is not None
    ceiling_height = n.number("ceiling_height", positive=True) if has_ceiling else None
    return Room(
        floor=_texture(n.child("floor", _TEXTURE), d.floor),
        ceiling_height=ceiling_height,
        ceiling=_texture(n.child("ceiling", _TEXTURE), d.ceiling),
        background=n.number("background", d.background, lo=0.0, hi=255.0),
    )


def _robot(n: _Node, pan_limits: tuple[float, float]) -> RobotPlan:
    start = n.child("start", ("x", "y", "theta_deg"))
    odo = n.child("odometry", ("trans_per_m", "rot_per_m_deg", "rot_per_rad", "trans_per_rad"))
    d = OdometryNoise()
    pan = n.child("pan", ("policy", "angle_deg"))
    angle = math.radians(pan.number("angle_deg", 0.0))
    if not pan_limits[0] <= angle <= pan_limits[1]:
        raise ConfigError(expected("an angle inside camera.pan_limits_deg", math.degrees(angle),
                                   where=pan.where("angle_deg")))
    plan = RobotPlan(
        start=SE2(start.number("x", 0.0), start.number("y", 0.0), math.radians(start.number("theta_deg", 0.0))),
        path=tuple(_step(s) for s in n.items("path", ("forward", "turn_deg", "to"))),
        frame_spacing=n.number("frame_spacing", 0.1, positive=True),
        frame_turn=math.radians(n.number("frame_turn_deg", 10.0, positive=True)),
        odometry=OdometryNoise(**{k: odo.number(k, getattr(d, k), lo=0.0) for k in
                                  ("trans_per_m", "rot_per_m_deg", "rot_per_rad", "trans_per_rad")}),
        pan=PanPolicy(pan.text("policy", "fixed", choices=("fixed", "look_at_free_edges")), angle),
    )
    frames = count_frames(plan)
    if frames > MAX_FRAMES:
        raise ConfigError(f"{n.where('path')}: the path makes {frames:.0f} stereo frames, more than {MAX_FRAMES} "
                          "(a shorter path, or a larger frame_spacing or frame_turn_deg)")
    return plan


def count_frames(plan: RobotPlan) -> float:
    """How many stereo frames :func:`~stablemarks.motion.plan_path` takes along ``plan`` (start included),
    counted without building the poses (the count may be huge)."""
    x, y, theta = plan.start.x, plan.start.y, plan.start.theta
    count = 1.0

    def parts(amount: float, spacing: float) -> float:
        return max(1.0, math.ceil(amount / spacing - 1e-9))

    for step in plan.path:
        if isinstance(step, Turn):
            count += parts(abs(step.angle), plan.frame_turn)
            theta += step.angle
        elif isinstance(step, Forward):
            count += parts(step.distance, plan.frame_spacing)
            x, y = x + step.distance * math.cos(theta), y + step.distance * math.sin(theta)
        else:
            dx, dy = step.point[0] - x, step.point[1] - y
            dist = math.hypot(dx, dy)
            if dist > 1e-9:
                angle = float(wrap_angle(math.atan2(dy, dx) - theta))
                if abs(angle) > 1e-9:
                    count += parts(abs(angle), plan.frame_turn)
                count += parts(dist, plan.frame_spacing)
                x, y, theta = step.point[0], step.point[1], theta + angle
        if count > MAX_FRAMES:
            break
    return count


def _step(n: _Node) -> PathStep:
    if len(n.data) != 1:
        raise ConfigError(expected("one of {forward: m}, {turn_deg: deg}, {to: [x, y]}", n.data, where=n.where()))
    if "forward" in n.data:
        return Forward(n.number("forward", positive=True))
    if "turn_deg" in n.data:
        return Turn(math.radians(n.number("turn_deg")))
    return GoTo(n.numbers("to", 2, what="a list of 2 numbers [x, y] in metres"))
