"""``angles.csv``: each joint's angles per frame, as ``acscal trajectory`` writes them.

A header row, then one row per frame and joint, in time order per joint. The columns are
fixed (pipelines read them by name):

- ``time`` (s, or frame numbers for trajectories without times), ``joint`` (its name);
- a hinge: ``angle_deg`` (the second body of ``between`` turning relative to the first about
  the axis the artifact reports, right-hand rule, 0 at the zero instant), ``angle_std_deg``,
  ``wobble_deg`` (the rotation off the axis);
- a ball joint: ``rotvec_x_deg``, ``rotvec_y_deg``, ``rotvec_z_deg`` (the articulation since
  the zero instant as a rotation vector in the first body's frame), ``rotvec_std_deg`` (per
  component), ``euler_sequence`` and ``euler_1_deg`` ... ``euler_3_std_deg``.

Cells that do not apply to a joint's type are empty.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from itertools import chain, repeat
from pathlib import Path

import numpy as np

from acs_cli.core.angles import BallAngles, HingeAngles
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError
from acs_cli.io.csv_table import read_csv_table, write_csv_table

__all__ = ["ANGLE_COLUMNS", "JointAngleSeries", "read_angles_csv", "write_angles_csv"]

ANGLE_COLUMNS = (
    "time",
    "joint",
    "angle_deg",
    "angle_std_deg",
    "wobble_deg",
    "rotvec_x_deg",
    "rotvec_y_deg",
    "rotvec_z_deg",
    "rotvec_std_deg",
    "euler_sequence",
    "euler_1_deg",
    "euler_2_deg",
    "euler_3_deg",
    "euler_1_std_deg",
    "euler_2_std_deg",
    "euler_3_std_deg",
)


@dataclass(frozen=True)
class JointAngleSeries:
    """One joint's angles over its frames' ``times`` ``(n,)``; ``zero``: the frame (index into
    ``times``) at which they are zero, when known."""

    joint: str
    times: FloatArray
    angles: HingeAngles | BallAngles
    zero: int | None = None


def _nums(x: FloatArray) -> list[str]:
    """Each value with 6 decimals, an empty cell where it is not finite."""
    v = np.asarray(x, dtype=float).reshape(-1)
    finite = np.isfinite(v)
    if not finite.any():
        return [""] * v.size
    cells = (("%.6f\n" * v.size) % tuple(v.tolist())).split("\n")[:-1]  # one %-format
    for i in np.flatnonzero(~finite).tolist():
        cells[i] = ""
    return cells


def write_angles_csv(path: str | Path, series: list[JointAngleSeries]) -> None:
    """Write ``angles.csv`` atomically (module doc)."""
    blocks: list[Iterable[Sequence[str]]] = []
    for s in series:
        a = s.angles
        times = np.asarray(s.times, dtype=float).reshape(-1)
        n = times.size
        # the table a column at a time (a loop per row and cell costs several times more on
        # a long recording)
        cols: dict[str, Iterable[str]] = {c: repeat("", n) for c in ANGLE_COLUMNS}
        cols["time"] = list(map(repr, times.tolist()))
        cols["joint"] = repeat(s.joint, n)
        if isinstance(a, HingeAngles):
            cols["angle_deg"] = _nums(a.angle_deg[:n])
            cols["angle_std_deg"] = _nums(a.angle_std_deg[:n])
            cols["wobble_deg"] = _nums(a.wobble_deg[:n])
        else:
            for k, c in enumerate("xyz"):
                cols[f"rotvec_{c}_deg"] = _nums(a.rotvec_deg[:n, k])
            cols["rotvec_std_deg"] = _nums(a.rotvec_std_deg[:n, 0])
            cols["euler_sequence"] = repeat(a.sequence, n)
            for k in range(3):
                cols[f"euler_{k + 1}_deg"] = _nums(a.euler_deg[:n, k])
                cols[f"euler_{k + 1}_std_deg"] = _nums(a.euler_std_deg[:n, k])
        blocks.append(zip(*(cols[c] for c in ANGLE_COLUMNS), strict=True))
    write_csv_table(path, ANGLE_COLUMNS, chain.from_iterable(blocks))


def read_angles_csv(path: str | Path) -> dict[str, dict[str, np.ndarray]]:
    """Per joint, each column of :data:`ANGLE_COLUMNS` as an array (floats; NaN for an empty
    cell; ``euler_sequence`` as strings).

    Raises
    ------
    InputError
        Not an ``angles.csv``: another header, or a row of another length.
    """
    p = Path(path)
    out: dict[str, dict[str, list[str]]] = {}
    for row in read_csv_table(p, ANGLE_COLUMNS, "angles.csv"):
        cols = out.setdefault(row[1], {c: [] for c in ANGLE_COLUMNS})
        for c, v in zip(ANGLE_COLUMNS, row, strict=True):
            cols[c].append(v)
    parsed: dict[str, dict[str, np.ndarray]] = {}
    for joint, cols in out.items():
        parsed[joint] = {}
        for c, vals in cols.items():
            if c in ("joint", "euler_sequence"):
                parsed[joint][c] = np.asarray(vals, dtype=str)
                continue
            try:
                parsed[joint][c] = np.asarray([float(v) if v else np.nan for v in vals])
            except ValueError as exc:
                raise InputError(f"column {c}: {exc}", path=p) from exc
    return parsed
