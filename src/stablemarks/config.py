"""All thresholds in one configuration object, with the paper's defaults, loadable from YAML.

A configuration file holds any subset of the sections below; everything left out keeps its default::

    segments:  {gradient_threshold: 40, min_length: 20}
    matching:  {max_disparity: 64, min_similarity: 0.5}
    sad:       {block_size: 15, num_disparities: 64, lr_tolerance: 1.0}
    filter:    {tolerance: 1.0, min_support: 0.5}
    planes:    {gate_sigma: 3.0}
    landmarks: {boundary_sigma: 3.0, min_length_similarity: 0.7}
    ekf:       {max_updates_per_frame: 6}

Unknown sections or keys are rejected with a message naming them.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from .errors import ConfigError, InputError, expected
from .landmarks import LandmarkConfig
from .maps import read_yaml
from .planes import PlaneConfig
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
    """Columns either side of the segment searched for an agreeing disparity [px]: half the SAD window,
    because an edge at a depth discontinuity takes its disparity from whichever side the window matched
    (a low-texture plane, like a whiteboard, is matched only some pixels in from its edge)."""


def _ekf_config_type():
    from .estimation import EKFConfig

    return EKFConfig


@dataclass(frozen=True)
class Config:
    """Every threshold of the pipeline, grouped by stage."""

    segments: SegmentConfig = field(default_factory=SegmentConfig)
    matching: MatchConfig = field(default_factory=MatchConfig)
    sad: SADConfig = field(default_factory=SADConfig)
    filter: FilterConfig = field(default_factory=FilterConfig)
    planes: PlaneConfig = field(default_factory=PlaneConfig)
    landmarks: LandmarkConfig = field(default_factory=LandmarkConfig)
    ekf: Any = field(default_factory=lambda: _ekf_config_type()())

    def to_dict(self) -> dict:
        return {f.name: dataclasses.asdict(getattr(self, f.name)) for f in fields(self)}

    def with_overrides(self, overrides: dict, source: str = "config") -> Config:
        """A copy with ``{section: {key: value}}`` applied, validated like a file."""
        return parse_config(overrides, source, base=self)


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
            if key not in known:
                raise ConfigError(f"{source}: {name}.{key}: unknown setting (known: {', '.join(sorted(known))})")
            default = getattr(current, key)
            if isinstance(default, bool) and not isinstance(value, bool):
                raise ConfigError(expected("true or false", value, where=f"{source}: {name}.{key}"))
            if isinstance(default, int | float) and not isinstance(default, bool):
                if isinstance(value, bool) or not isinstance(value, int | float):
                    raise ConfigError(expected("a number", value, where=f"{source}: {name}.{key}"))
                if isinstance(default, int) and not isinstance(default, bool) and float(value) != int(value):
                    raise ConfigError(expected("a whole number", value, where=f"{source}: {name}.{key}"))
                value = type(default)(value)
            clean[key] = value
        try:
            updates[name] = replace(current, **clean)
        except InputError as exc:
            raise ConfigError(f"{source}: {name}: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{source}: {name}: {exc}") from None
    return replace(base, **updates)


def load_config(path: str | Path | None) -> Config:
    """Load a configuration file; ``None`` gives the defaults."""
    if path is None:
        return Config()
    return parse_config(read_yaml(path, "configuration file"), str(path))
