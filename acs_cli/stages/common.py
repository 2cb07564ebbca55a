"""What the stages share: pairing trajectories, the pairing section."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, TypeVar

from acs_cli.core.pairing import PairingResult, pair_trajectories
from acs_cli.io.joint import Pairing
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import Trajectory
from acs_cli.io.validate import TIME_TOL

__all__ = [
    "PAIR_BY",
    "TIME_TOL",
    "PairedTrajectories",
    "StageRun",
    "input_files",
    "load_poses",
    "pair_loaded",
    "pairing_section",
]

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


def load_poses(poses: Path | PosesArtifact, fmt: str = "auto") -> PosesArtifact:
    """A camera's poses input: read once from its file (:meth:`PosesArtifact.load`), or as
    a caller that read it already (``acscal run``, which hashed it) hands it down."""
    return poses if isinstance(poses, PosesArtifact) else PosesArtifact.load(poses, fmt)


def input_files(inputs: Mapping[str, Path | PosesArtifact]) -> list[Path]:
    """The files of a stage's inputs (poses made in memory have none)."""
    files = [p if isinstance(p, Path) else p.source for p in inputs.values()]
    return [Path(p) for p in files if p is not None]


def pair_loaded(
    a: Trajectory, b: Trajectory, pair_by: str = "auto", max_dt: float | None = None
) -> PairedTrajectories:
    """Two trajectories reduced to their paired samples, and a warning for the others."""
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
