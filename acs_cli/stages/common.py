"""What the stages share: loading and pairing trajectories, the pairing section."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, TypeVar

from acs_cli.core.pairing import PairingResult, pair_trajectories
from acs_cli.io.joint import Pairing
from acs_cli.io.trajectory import Trajectory, read_trajectory
from acs_cli.io.validate import TIME_TOL

__all__ = [
    "PAIR_BY",
    "TIME_TOL",
    "TRAJECTORY_FORMATS",
    "PairedTrajectories",
    "StageRun",
    "load_pair",
    "load_trajectory",
    "pair_loaded",
    "pairing_section",
]

TRAJECTORY_FORMATS = ("auto", "tum", "kitti", "colmap", "npz")

E = TypeVar("E")


@dataclass(frozen=True)
class StageRun(Generic[E]):
    """What a stage's ``run_*`` did: the estimate, the artifact (header and body) it wrote,
    where, and the run's warnings."""

    estimate: E
    artifact: dict[str, Any]
    output: Path
    warnings: list[str] = field(default_factory=list)


PAIR_BY = ("auto", "timestamp", "index")


@dataclass(frozen=True)
class PairedTrajectories:
    """Two trajectories reduced to their paired frames.

    Attributes
    ----------
    a, b : Trajectory
        Paired samples only, in pair order (``a.T_world_cam[i]`` with ``b.T_world_cam[i]``).
    pairing : PairingResult
        Indices into the original trajectories and the counts left unpaired.
    """

    a: Trajectory
    b: Trajectory
    pairing: PairingResult
    warnings: list[str] = field(default_factory=list)


def load_trajectory(path: Path, fmt: str = "auto") -> Trajectory:
    """Read a trajectory file (see :func:`acs_cli.io.trajectory.read_trajectory`)."""
    return read_trajectory(path, fmt)


def load_pair(
    path_a: Path,
    path_b: Path,
    fmt_a: str = "auto",
    fmt_b: str = "auto",
    pair_by: str = "auto",
    max_dt: float | None = None,
) -> PairedTrajectories:
    """Read two trajectories and keep their paired samples."""
    return pair_loaded(
        read_trajectory(path_a, fmt_a), read_trajectory(path_b, fmt_b), pair_by, max_dt
    )


def pair_loaded(
    a: Trajectory, b: Trajectory, pair_by: str = "auto", max_dt: float | None = None
) -> PairedTrajectories:
    """Pair two trajectories already read (see :func:`load_pair`)."""
    pairing = pair_trajectories(a, b, pair_by, max_dt)
    warnings = []
    if pairing.unpaired_a or pairing.unpaired_b:
        warnings.append(
            f"{pairing.unpaired_a} of {len(a)} poses of A and {pairing.unpaired_b} of {len(b)} "
            "poses of B have no partner and were left out"
        )
    return PairedTrajectories(a.select(pairing.idx_a), b.select(pairing.idx_b), pairing, warnings)


def pairing_section(p: PairingResult, by: str) -> Pairing:
    """The ``quality.pairing`` section of an artifact: how ``p`` paired, ``by`` as asked."""
    return Pairing(
        by="index" if p.max_dt is None else "timestamp",
        requested=by,
        pairs=int(p.n_pairs),
        unpaired_a=int(p.unpaired_a),
        unpaired_b=int(p.unpaired_b),
        max_dt_s=None if p.max_dt is None else float(p.max_dt),
    )
