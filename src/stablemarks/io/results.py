"""Writing results: per-frame landmark results (``landmarks.csv``, ``landmarks.json``; metres, map frame),
an on-line run's folder (:func:`write_run`) and its per-frame log streamed while it runs (:class:`LogWriter`)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

LANDMARK_COLUMNS = (
    "plane", "index", "x", "y", "z_low", "z_high", "length", "sigma_x", "sigma_y",
    "length_similarity", "selected", "reason",
)
"""The columns of ``landmarks.csv`` (issue contract); metres, map frame."""


def candidate_row(c) -> dict:
    """One :class:`~stablemarks.landmarks.Candidate` as a row of ``landmarks.csv``."""
    return {
        "plane": c.plane_id,
        "index": c.index,
        "x": float(c.P[0]),
        "y": float(c.P[1]),
        "z_low": c.z_low,
        "z_high": c.z_high,
        "length": c.length,
        "sigma_x": float(np.sqrt(max(c.cov[0, 0], 0.0))),
        "sigma_y": float(np.sqrt(max(c.cov[1, 1], 0.0))),
        "length_similarity": c.length_similarity,
        "selected": bool(c.selected),
        "reason": c.reason,
    }


def candidate_record(c) -> dict:
    """The JSON record: the CSV row plus the model's details (edge, d_p, σ_b, σ_f, covariance, image columns)."""
    row = candidate_row(c)
    row.update(
        plane_label=c.plane_label,
        edge=c.edge,
        s=c.s,
        sigma_s=c.sigma_s,
        sigma_boundary=c.sigma_b,
        sigma_feature=c.sigma_f,
        cov=np.asarray(c.cov).tolist(),
        u_left=c.u_left,
        u_right=c.u_right,
        v_top=c.v_top,
        v_bottom=c.v_bottom,
    )
    return row


def write_landmarks(out_dir: str | Path, candidates, extra: dict | None = None) -> tuple[Path, Path]:
    """Write ``landmarks.csv`` and ``landmarks.json`` (one row/record per candidate feature)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    csv_path, json_path = out / "landmarks.csv", out / "landmarks.json"
    rows = [candidate_row(c) for c in candidates]
    tmp = csv_path.with_suffix(".csv.tmp")
    with tmp.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=LANDMARK_COLUMNS)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6f}" if isinstance(v, float) else v) for k, v in r.items()})
    tmp.replace(csv_path)
    doc = {"units": "m", "frame": "map", "landmarks": [candidate_record(c) for c in candidates]}
    if extra:
        doc.update(extra)
    tmp = json_path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(doc, indent=2))
    tmp.replace(json_path)
    return csv_path, json_path


def _atomic_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)


def log_line(record) -> str:
    """One frame's line of ``log.jsonl``: its :class:`~stablemarks.localizer.FrameRecord` as JSON."""
    return json.dumps(record.to_dict()) + "\n"


class LogWriter:
    """An observer of :func:`stablemarks.online.run_online` writing ``log.jsonl`` as the run goes: one JSON
    line per frame (:func:`log_line`), flushed after each, so that an interrupted run keeps the log of the
    frames it did and the loop need not hold the records (``run_online(..., keep="poses")``).

    A context manager: ``with LogWriter(out / "log.jsonl") as log: run_online(..., observers=[log])``. The
    file is written in place (no temporary file: what is there when the run stops is the log so far).
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.frames = 0
        self._fh = None

    def __enter__(self) -> LogWriter:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = self.path.open("w", encoding="utf-8")
        return self

    def __call__(self, frame, est, localizer) -> None:
        if self._fh is None:
            raise RuntimeError("LogWriter: use it as a context manager (with LogWriter(path) as log: ...)")
        self._fh.write(log_line(est.record))
        self._fh.flush()
        self.frames += 1

    def __exit__(self, *exc) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def write_run(out_dir: str | Path, result, config=None, *, log: str | Path | None = None) -> dict[str, Path]:
    """Write an on-line run's results (REP-103/105: map frame; planar covariance over x, y, yaw):

    ``trajectory.tum`` (the estimate), ``dead_reckoning.tum`` (odometry alone, same stamps),
    ``groundtruth.tum`` when the truth is known, ``landmarks.yaml`` (the landmark map with covariances,
    loadable as prior landmarks with ``--prior-landmarks``), ``log.jsonl`` (one line per frame) and
    ``config.yaml`` (the resolved configuration).

    ``log``: the ``log.jsonl`` a :class:`LogWriter` already wrote during the run (it is listed, not written
    again; the result may then hold a :class:`~stablemarks.online.PoseRecord` per frame). Without it the log
    is written from ``result.records``, which must be whole :class:`~stablemarks.localizer.FrameRecord` objects.
    """
    import yaml

    from ..localizer import landmark_map_document
    from .trajectory import write_tum

    if log is None and any(not hasattr(r, "to_dict") for r in result.records):
        raise ValueError("write_run: the run kept only its poses (keep='poses'): stream its log with LogWriter and "
                         "pass log=")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    stamps = result.stamps
    for name, poses in (("trajectory", result.poses), ("dead_reckoning", result.dead_reckoning),
                        ("groundtruth", result.true_poses)):
        if poses is None:
            continue
        tmp = out / f".{name}.tum.tmp"
        write_tum(tmp, stamps, poses)
        tmp.replace(out / f"{name}.tum")
        paths[name] = out / f"{name}.tum"
    doc = landmark_map_document(result.ekf, result.method)
    _atomic_text(out / "landmarks.yaml", yaml.safe_dump(doc, sort_keys=False))
    paths["landmarks"] = out / "landmarks.yaml"
    if log is None:
        _atomic_text(out / "log.jsonl", "".join(log_line(r) for r in result.records))
        paths["log"] = out / "log.jsonl"
    else:
        paths["log"] = Path(log)
    if config is not None:
        _atomic_text(out / "config.yaml", yaml.safe_dump(config.to_dict(), sort_keys=False))
        paths["config"] = out / "config.yaml"
    return paths
