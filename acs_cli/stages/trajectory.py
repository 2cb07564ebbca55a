"""The trajectory stage: ``acscal trajectory`` (the ACS's path in one frame).

Reads a ``relpose.yaml`` (the relative pose ``T_b_a`` at its reference instant, and the
scale under unknown scale), the joint (from ``relpose.yaml`` itself, or ``--joint``) and the
two trajectories; pairs A's and B's samples as ``acscal relpose`` does; writes
``cam_a.tum``, ``cam_b.tum``, ``joint.tum`` (``T_world_X`` with world = camera A at the
reference instant, A's units) and ``trajectory.yaml`` (the joint constraint's consistency
per frame). The maths is :mod:`acs_cli.core.acs_trajectory`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.core.acs_trajectory import AcsTrajectory, recover_trajectory
from acs_cli.errors import InputError
from acs_cli.io.artifacts import (
    get_path,
    make_header,
    read_yaml_artifact,
    sha256_of,
    write_yaml_artifact,
)
from acs_cli.io.atomic import check_distinct_output
from acs_cli.io.trajectory import write_tum
from acs_cli.stages.common import (
    TIME_TOL,
    PairedTrajectories,
    StageRun,
    finite_vec3,
    load_pair,
    pairing_section,
)
from acs_cli.stages.joint import read_joint

__all__ = [
    "OUTPUT_NAMES",
    "TrajectoryConfig",
    "TrajectoryRun",
    "read_relpose",
    "recover_from_relpose",
    "run_trajectory",
]

#: Files ``run_trajectory`` writes into its output folder.
OUTPUT_NAMES = {
    "cam_a": "cam_a.tum",
    "cam_b": "cam_b.tum",
    "joint": "joint.tum",
    "artifact": "trajectory.yaml",
}


@dataclass(frozen=True)
class TrajectoryConfig:
    """Options of the trajectory stage.

    Attributes
    ----------
    format_a, format_b : str
        Trajectory file formats (``auto`` sniffs).
    pair_by : {"auto", "timestamp", "index"}
        How A's and B's samples are paired; ``auto`` with ``max_dt`` None repeats the
        pairing ``relpose.yaml`` records.
    max_dt : float, optional
        Largest timestamp difference of a pair, seconds.
    """

    format_a: str = "auto"
    format_b: str = "auto"
    pair_by: str = "auto"
    max_dt: float | None = None


@dataclass(frozen=True)
class RecoveredTrajectory:
    """A trajectory recovered from a relpose artifact, with what it was made from.

    Attributes
    ----------
    trajectory : AcsTrajectory
    pair : PairedTrajectories
        The paired samples (A's and B's timestamps).
    rejected : ndarray of bool, shape (n,)
        Frames ``relpose.yaml`` rejected as outliers.
    joint_source : str
        Where the joint came from.
    position_in_a, position_in_b : ndarray (3,)
        The joint used, in A units and B units.
    length_unit : str
        The unit of the outputs (``A units`` under unknown scale).
    mu_a : float or None
        A units per metre, when ``relpose.yaml`` knows it.
    """

    trajectory: AcsTrajectory
    pair: PairedTrajectories
    rejected: np.ndarray
    joint_source: str
    position_in_a: np.ndarray
    position_in_b: np.ndarray
    length_unit: str
    mu_a: float | None


TrajectoryRun = StageRun[RecoveredTrajectory]


#: Keys of ``relpose.yaml`` the trajectory needs.
RELPOSE_KEYS = (
    "relative_pose.T_b_a",
    "relative_pose.reference",
    "joint.position_in_a",
    "joint.position_in_b",
)


def read_relpose(path: Path) -> dict[str, Any]:
    """A ``relpose.yaml`` with the keys the trajectory needs (``InputError`` otherwise)."""
    return read_yaml_artifact(path, "relpose", RELPOSE_KEYS)


def _number(value: Any, what: str, path: Path) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{what} must be a number, got {value!r}", path=path)
    return float(value)


def _scale(doc: dict[str, Any], path: Path) -> tuple[float, float | None, float | None]:
    """``phi_ba``, ``mu_a``, ``mu_b`` of a relpose artifact (1, None, None without scale)."""
    scale = doc.get("scale")
    if scale is None:
        return 1.0, None, None
    if not isinstance(scale, dict):
        raise InputError("'scale' must be a mapping", path=path)
    phi = _number(scale.get("phi_ba"), "scale.phi_ba", path)
    if phi is None or not (np.isfinite(phi) and phi > 0):
        raise InputError(f"scale.phi_ba must be a positive number, got {phi!r}", path=path)
    mu_a = _number(scale.get("mu_a"), "scale.mu_a", path)
    mu_b = _number(scale.get("mu_b"), "scale.mu_b", path)
    return phi, mu_a, mu_b


def _reference_index(rel: dict[str, Any], pair: PairedTrajectories, path: Path) -> int:
    """The paired frame at ``relpose.yaml``'s reference instant (by timestamps when known)."""
    ta_ref = rel.get("reference_timestamp_a")
    tb_ref = rel.get("reference_timestamp_b")
    if ta_ref is None or tb_ref is None:
        k = rel["reference"]
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k < len(pair.a):
            raise InputError(
                f"relative_pose.reference = {k!r} is not one of the {len(pair.a)} paired frames",
                path=path,
            )
        return int(k)
    ta = float(_number(ta_ref, "relative_pose.reference_timestamp_a", path) or 0.0)
    tb = float(_number(tb_ref, "relative_pose.reference_timestamp_b", path) or 0.0)
    hit = np.flatnonzero(
        (np.abs(pair.a.timestamps - ta) <= TIME_TOL) & (np.abs(pair.b.timestamps - tb) <= TIME_TOL)
    )
    if hit.size == 0:
        raise InputError(
            f"the reference instant of relpose.yaml (A at {ta}, B at {tb}) is not among the "
            "paired samples of these trajectories; give the trajectories relpose was "
            "estimated from (its inputs.poses_a and inputs.poses_b)",
            path=path,
        )
    return int(hit[0])


def _rejected_mask(doc: dict[str, Any], pair: PairedTrajectories) -> np.ndarray:
    """Frames listed in ``quality.frames.rejected`` (A's timestamps), as a mask."""
    listed = get_path(doc, "quality.frames.rejected", [])
    mask = np.zeros(len(pair.a), dtype=bool)
    if not isinstance(listed, list):
        return mask
    values = np.asarray([v for v in listed if isinstance(v, (int, float))], dtype=float)
    if values.size:
        mask = np.any(np.abs(pair.a.timestamps[:, None] - values[None, :]) <= TIME_TOL, axis=1)
    return mask


def recover_from_relpose(
    relpose_doc: dict[str, Any],
    relpose_path: Path,
    pair: PairedTrajectories,
    joint_path: Path | None = None,
) -> RecoveredTrajectory:
    """The ACS's trajectory from a read ``relpose.yaml`` and the paired trajectories.

    Parameters
    ----------
    relpose_doc : dict
        From :func:`read_relpose`.
    relpose_path : Path
        Its file (for messages).
    pair : PairedTrajectories
        A's and B's paired samples (the trajectories relpose was estimated from).
    joint_path : Path, optional
        A ``joint.yaml`` whose positions replace ``relpose.yaml``'s joint. Under unknown scale
        its positions are taken in the trajectories' units, or as metres when
        ``relpose.yaml`` knows ``mu_a`` and ``mu_b`` (``--joint-metric``).

    Raises
    ------
    InputError
        Malformed artifacts, or a reference instant not among the paired samples.
    """
    for key in RELPOSE_KEYS:
        get_path(relpose_doc, key, source=relpose_path)
    rel = relpose_doc["relative_pose"]
    if not isinstance(rel, dict):
        raise InputError("'relative_pose' must be a mapping", path=relpose_path)
    try:
        T_b_a = np.asarray(rel["T_b_a"], dtype=float)
    except (TypeError, ValueError):
        T_b_a = np.zeros(0)
    if T_b_a.shape != (4, 4) or not np.all(np.isfinite(T_b_a)):
        raise InputError("relative_pose.T_b_a must be a finite 4x4 matrix", path=relpose_path)
    phi, mu_a, mu_b = _scale(relpose_doc, relpose_path)
    if joint_path is None:
        joint = relpose_doc["joint"]
        o_a = finite_vec3(joint.get("position_in_a"), "joint.position_in_a", relpose_path)
        o_b = finite_vec3(joint.get("position_in_b"), "joint.position_in_b", relpose_path)
        source = f"{relpose_path} (joint estimated with the relative pose)"
    else:
        joint = read_joint(joint_path)
        o_a = finite_vec3(joint.get("position_in_a"), "joint.position_in_a", joint_path)
        if joint.get("position_in_b") is None:
            raise InputError(
                "has no joint.position_in_b: the trajectory needs the joint in both cameras "
                "(or leave out --joint to use relpose.yaml's joint)",
                path=joint_path,
            )
        o_b = finite_vec3(joint.get("position_in_b"), "joint.position_in_b", joint_path)
        source = str(joint_path)
        if mu_a is not None and mu_b is not None:
            o_a, o_b = o_a * mu_a, o_b * mu_b
            source += " (metric, scaled by mu_a and mu_b of relpose.yaml)"
    k = _reference_index(rel, pair, relpose_path)
    try:
        traj = recover_trajectory(
            pair.a.T_world_cam, pair.b.T_world_cam, T_b_a, o_a, o_b, reference=k, phi_ba=phi
        )
    except InputError as exc:
        raise InputError(exc.message, path=relpose_path) from exc
    unknown_scale = relpose_doc.get("scale") is not None
    units = relpose_doc.get("units")
    unit = units.get("length", "m") if isinstance(units, dict) else "m"
    length_unit = "A units" if unknown_scale else str(unit)
    rejected = _rejected_mask(relpose_doc, pair)
    return RecoveredTrajectory(traj, pair, rejected, source, o_a, o_b, length_unit, mu_a)


def _check_inputs_match(doc: dict[str, Any], poses_a: Path, poses_b: Path) -> list[str]:
    """Warnings when the trajectories are not the ones ``relpose.yaml`` was made from."""
    warnings: list[str] = []
    inputs = doc.get("inputs")
    if not isinstance(inputs, dict):
        return warnings
    for role, given in (("poses_a", poses_a), ("poses_b", poses_b)):
        rec = inputs.get(role)
        if isinstance(rec, dict) and rec.get("sha256") and rec["sha256"] != sha256_of(given):
            warnings.append(
                f"{given} differs from the {role} relpose.yaml was estimated from "
                f"({rec.get('path')})"
            )
    return warnings


def run_trajectory(
    relpose: Path,
    poses_a: Path,
    poses_b: Path,
    out_dir: Path,
    config: TrajectoryConfig | None = None,
    joint: Path | None = None,
) -> TrajectoryRun:
    """Recover the ACS's trajectory and write ``cam_a.tum``, ``cam_b.tum``, ``joint.tum`` and
    ``trajectory.yaml`` into ``out_dir`` (each atomically).

    Raises
    ------
    InputError
        Bad files or options; ``out_dir`` is a file; an output would overwrite an input.
    """
    cfg = config or TrajectoryConfig()
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("is a file; -o takes a folder for the trajectory files", path=out_dir)
    inputs: dict[str, Path] = {"relpose": relpose, "poses_a": poses_a, "poses_b": poses_b}
    if joint is not None:
        inputs["joint"] = joint
    outputs = {key: out_dir / name for key, name in OUTPUT_NAMES.items()}
    for out in outputs.values():
        check_distinct_output(out, inputs.values())
    doc = read_relpose(relpose)
    pair_by, max_dt = cfg.pair_by, cfg.max_dt
    recorded = get_path(doc, "quality.pairing", None)
    if pair_by == "auto" and max_dt is None and isinstance(recorded, dict):
        req = recorded.get("requested")
        pair_by = req if req in ("auto", "timestamp", "index") else "auto"
        md = recorded.get("max_dt_s")
        max_dt = float(md) if isinstance(md, (int, float)) and not isinstance(md, bool) else None
    pair = load_pair(poses_a, poses_b, cfg.format_a, cfg.format_b, pair_by, max_dt)
    rec = recover_from_relpose(doc, relpose, pair, joint)
    warnings = list(pair.warnings) + _check_inputs_match(doc, poses_a, poses_b)
    traj = rec.trajectory
    n_rej = int(rec.rejected.sum())
    if n_rej:
        warnings.append(f"{n_rej} frame(s) were rejected as outliers by relpose (marked)")

    write_tum(outputs["cam_a"], pair.a.timestamps, traj.T_r_a)
    write_tum(outputs["cam_b"], pair.b.timestamps, traj.T_r_b)
    write_tum(outputs["joint"], pair.a.timestamps, traj.T_r_joint)

    d = traj.consistency
    used = ~rec.rejected if (~rec.rejected).any() else np.ones_like(rec.rejected)
    body: dict[str, Any] = {
        "reference": {
            "index": traj.reference,
            "timestamp_a": float(pair.a.timestamps[traj.reference]),
            "timestamp_b": float(pair.b.timestamps[traj.reference]),
        },
        "scale": {
            "phi_ba": traj.phi_ba,
            "applied": "B's translations, T_b_a's translation and position_in_b divided by "
            "phi_ba (B units to A units)"
            if doc.get("scale") is not None
            else "none (known scale)",
            "mu_a": rec.mu_a,
        },
        "joint": {
            "source": rec.joint_source,
            "position_in_a": rec.position_in_a.tolist(),
            "position_in_b": rec.position_in_b.tolist(),
        },
        "outputs": {key: name for key, name in OUTPUT_NAMES.items() if key != "artifact"},
        "consistency": {
            "rms": float(np.sqrt(np.mean(d[used] ** 2))),
            "median": float(np.median(d[used])),
            "max": float(d[used].max()),
            "frames": {
                "timestamp_a": pair.a.timestamps.tolist(),
                "timestamp_b": pair.b.timestamps.tolist(),
                "distance": d.tolist(),
                "rejected": rec.rejected.tolist(),
            },
        },
        "quality": {"pairing": pairing_section(pair.pairing, pair_by)},
        "warnings": warnings,
    }
    header = make_header(
        "trajectory",
        inputs,
        method="T_r_a[i] = inv(T_wa_a[k]) T_wa_a[i]; T_r_b[i] = inv(T_b_a) inv(T_wb_b[k]) "
        "T_wb_b[i] (k the reference instant, B's lengths divided by phi_ba); the joint at "
        "T_r_a[i] o_a (from A) and T_r_b[i] o_b (from B)",
        units={
            "length": "A units (camera A's trajectory units: mu_a x metres)"
            if doc.get("scale") is not None
            else rec.length_unit,
            "timestamps": "s (or frame numbers for trajectories without timestamps)",
            "position_in_b": "B units" if doc.get("scale") is not None else rec.length_unit,
        },
        frames={
            "world": "camera A's optical frame at the reference instant",
            "cam_a.tum": "T_world_a: camera A's pose",
            "cam_b.tum": "T_world_b: camera B's pose",
            "joint.tum": "T_world_joint: the joint (as camera A sees it), camera A's orientation",
            "consistency.frames.distance": "|joint from A - joint from B| in the world frame",
        },
    )
    write_yaml_artifact(outputs["artifact"], header, body)
    return StageRun(rec, header | body, outputs["artifact"], warnings)
