"""``joint_residuals.csv``: each joint's constraint residual at every frame of a rig run.

``acscal run`` writes it beside ``rig.yaml``: the residuals of the pose-based solve
(:func:`acs_cli.core.rig_solve.estimate_rig`), the rows its ``residual_rms`` and outlier
test are made of, at every frame of each joint, the rejected ones too. A header row, then one
row per joint and frame, in time order per joint and recording. The columns are fixed
(pipelines read them by name):

- ``time`` (s, or frame numbers for trajectories without times, on the rig's timeline),
  ``recording`` (its name; ``default`` in a config of one recording), ``joint`` (its name);
- ``used``: 1 when the solve used the frame, 0 when it rejected it as an outlier;
- ``position``: a ball or hinge joint's point residual ``|G_p o_p - G_q o_q|`` (the joint as
  each of its two bodies carries it), in ``rig.yaml``'s ``length_unit``;
- ``rotation_deg``: a hinge's axis residual ``|R_p u_p - R_q u_q|`` (the axis as each body
  carries it; its RMS is ``wobble_rms_deg``), or a rigid joint's rotation residual
  ``|log(R_p^T R_q R_q_p)|``, in degrees (the rows' norm in radians, times 180/pi);
- ``translation``: a rigid joint's translation residual at the midpoint between its two
  cameras, in ``length_unit``.

Cells that do not apply to a joint's type are empty (:attr:`JointModel.residual_kinds
<acs_cli.core.joints.base.JointModel.residual_kinds>` says which apply).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError
from acs_cli.io.csv_table import read_csv_table, write_csv_table

__all__ = [
    "KIND_COLUMNS",
    "RESIDUALS_FILE",
    "RESIDUAL_COLUMNS",
    "JointResiduals",
    "read_joint_residuals",
    "write_joint_residuals",
]

#: The file's name in a rig run folder (beside ``rig.yaml``).
RESIDUALS_FILE = "joint_residuals.csv"

RESIDUAL_COLUMNS = ("time", "recording", "joint", "used", "position", "rotation_deg", "translation")

#: The column of each residual kind (:attr:`JointModel.residual_kinds`).
KIND_COLUMNS = {"pos": "position", "rot": "rotation_deg", "trans": "translation"}


@dataclass(frozen=True)
class JointResiduals:
    """One joint's residual per frame of one recording.

    Attributes
    ----------
    joint, recording : str
    times : ndarray, shape (n,)
        The frames' times on the rig's timeline.
    used : ndarray of bool, shape (n,)
        False where the solve rejected the frame as an outlier.
    values : dict of str to ndarray, shape (n,)
        The residual's norm per frame by kind (``pos``, ``rot``, ``trans``): lengths in the
        rig's unit, ``rot`` in degrees.
    """

    joint: str
    recording: str
    times: FloatArray
    used: np.ndarray
    values: dict[str, FloatArray] = field(default_factory=dict)


def _num(x: float) -> str:
    return "" if not np.isfinite(x) else repr(float(x))


def write_joint_residuals(path: str | Path, series: list[JointResiduals]) -> None:
    """Write ``joint_residuals.csv`` atomically (module doc).

    Raises
    ------
    ValueError
        A residual kind without a column (a joint type this file does not know).
    """
    rows: list[list[str]] = []
    for s in series:
        unknown = set(s.values) - set(KIND_COLUMNS)
        if unknown:
            raise ValueError(f"joint {s.joint}: no column for residual kind(s) {sorted(unknown)}")
        cols = {KIND_COLUMNS[k]: v for k, v in s.values.items()}
        for i, t in enumerate(np.asarray(s.times, dtype=float)):
            row = [repr(float(t)), s.recording, s.joint, "1" if s.used[i] else "0"]
            row += [_num(cols[c][i]) if c in cols else "" for c in RESIDUAL_COLUMNS[4:]]
            rows.append(row)
    write_csv_table(path, RESIDUAL_COLUMNS, rows)


def read_joint_residuals(path: str | Path) -> list[JointResiduals]:
    """Every joint's residuals, one :class:`JointResiduals` per joint and recording, in the
    file's order; a kind whose cells are all empty is left out.

    Raises
    ------
    InputError
        Not a ``joint_residuals.csv``: another header, a row of another length, a cell that
        is not a number.
    """
    p = Path(path)
    groups: dict[tuple[str, str], list[list[str]]] = {}
    for n, row in enumerate(read_csv_table(p, RESIDUAL_COLUMNS, RESIDUALS_FILE), start=2):
        if row[3] not in ("0", "1"):
            raise InputError(f"column used: {row[3]!r} is not 0 or 1", path=p, line=n)
        groups.setdefault((row[2], row[1]), []).append(row)
    out = []
    for (joint, recording), got in groups.items():
        try:
            cells = np.array(
                [[float(v) if v else np.nan for v in (r[0], *r[4:])] for r in got], dtype=float
            )
        except ValueError as exc:
            raise InputError(f"joint {joint}: {exc}", path=p) from exc
        values = {
            kind: cells[:, 1 + RESIDUAL_COLUMNS[4:].index(col)]
            for kind, col in KIND_COLUMNS.items()
        }
        out.append(
            JointResiduals(
                joint,
                recording,
                cells[:, 0],
                np.array([r[3] == "1" for r in got]),
                {k: v for k, v in values.items() if np.isfinite(v).any()},
            )
        )
    return out
