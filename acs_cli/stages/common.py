"""What the stages share: loading and pairing trajectories, artifact sections."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Generic, TypeVar

import numpy as np

from acs_cli.core.pairing import PairingResult, pair_trajectories
from acs_cli.errors import InputError
from acs_cli.io.trajectory import Trajectory, read_trajectory

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


#: Largest difference (seconds or frame numbers) for two timestamps to be the same sample.
TIME_TOL = 1e-6


def finite_vec3(value: Any, what: str, path: Path | None) -> np.ndarray:
    """Three finite numbers from an artifact's value, or an :class:`InputError` naming
    ``what`` and the file."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise InputError(f"{what} must be three finite numbers", path=path)
    return arr


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
    a = read_trajectory(path_a, fmt_a)
    b = read_trajectory(path_b, fmt_b)
    pairing = pair_trajectories(a, b, pair_by, max_dt)
    warnings = []
    if pairing.unpaired_a or pairing.unpaired_b:
        warnings.append(
            f"{pairing.unpaired_a} of {len(a)} poses of A and {pairing.unpaired_b} of {len(b)} "
            "poses of B have no partner and were left out"
        )
    return PairedTrajectories(a.select(pairing.idx_a), b.select(pairing.idx_b), pairing, warnings)


def pairing_section(p: PairingResult, by: str) -> dict[str, Any]:
    """The ``quality.pairing`` section of an artifact."""
    return {
        "by": "index" if p.max_dt is None else "timestamp",
        "requested": by,
        "pairs": int(p.n_pairs),
        "unpaired_a": int(p.unpaired_a),
        "unpaired_b": int(p.unpaired_b),
        "max_dt_s": None if p.max_dt is None else float(p.max_dt),
    }


def frames_section(inliers: np.ndarray, labels: np.ndarray | None = None) -> dict[str, Any]:
    """``{total, used, rejected: [...]}`` for a mask of the frames used.

    ``rejected`` lists the original indices (or timestamps, via ``labels``) of dropped frames.
    """
    rejected = np.flatnonzero(~inliers)
    listed = rejected if labels is None else np.asarray(labels)[rejected]
    return {
        "total": int(inliers.size),
        "used": int(inliers.sum()),
        "rejected": [x.item() for x in listed],
    }


def vector_with_std(
    value: np.ndarray, cov: np.ndarray | None
) -> tuple[list[float], list[float] | None]:
    """A 3-vector and its standard deviations from a covariance."""
    std = None if cov is None else np.sqrt(np.maximum(np.diag(cov), 0.0)).tolist()
    return np.asarray(value, dtype=float).tolist(), std
