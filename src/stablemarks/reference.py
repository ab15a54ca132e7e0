"""The paper's published figures, for side-by-side comparison (paper.md, Table 1). Units as printed: mm."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Table1Row:
    plane: str
    index: int
    x: float
    y: float
    length: float
    sigma_x: float
    sigma_y: float
    length_similarity: float
    selected: bool
    reason: str


def _rows():
    raw = """\
partition 1 0.1 4000.0 1309.0 28.3 0.0 0.5 No near_boundary
partition 2 109.4 4000.0 487.0 35.0 0.0 1.0 No near_boundary
partition 3 177.8 4000.0 270.0 35.0 0.0 0.9 Yes -
partition 4 411.0 4000.0 258.0 35.0 0.0 1.0 Yes -
partition 5 483.0 4000.0 490.0 35.0 0.0 1.0 Yes -
partition 6 605.1 4000.0 1542.0 35.0 0.0 1.0 Yes -
partition 7 643.7 4000.0 1557.0 35.8 0.0 1.0 Yes -
whiteboard 1 -550.2 6000.0 584.0 54.2 0.0 0.8 No near_boundary
whiteboard 2 -622.6 6000.0 279.0 46.4 0.0 0.9 No near_boundary
whiteboard 3 -698.3 6000.0 841.0 47.0 0.0 1.0 No near_boundary
whiteboard 4 -1004.3 6000.0 245.0 50.4 0.0 0.9 Yes -
whiteboard 5 -1076.0 6000.0 261.0 51.0 0.0 0.9 Yes -
whiteboard 6 -1309.9 6000.0 361.0 53.1 0.0 1.0 Yes -
whiteboard 7 -1380.9 6000.0 376.0 53.9 0.0 1.0 Yes -"""
    for line in raw.splitlines():
        p, i, x, y, l, sx, sy, ls, sel, reason = line.split()
        yield Table1Row(p, int(i), float(x), float(y), float(l), float(sx), float(sy), float(ls), sel == "Yes",
                        "" if reason == "-" else reason.replace("_", " "))


TABLE1: tuple[Table1Row, ...] = tuple(_rows())
"""Table 1 of the paper: modelled features on the partition and the white board [mm]."""
