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
from acs_cli.core.angles import (
    BallAngles,
    HingeAngles,
    articulation_from_orientations,
    ball_angles,
    check_euler_sequence,
    hinge_angles,
)
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError
from acs_cli.io.angles import JointAngleSeries, write_angles_csv
from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.atomic import check_distinct_output, check_writable
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.relpose import RelposeArtifact
from acs_cli.io.rig import RigArtifact
from acs_cli.io.trajectory import FRAME_NUMBERS_NOTE, write_tum
from acs_cli.io.validate import TIME_TOL
from acs_cli.io.verdict import weak_marks
from acs_cli.stages.common import (
    PairedTrajectories,
    StageRun,
    input_files,
    pair_loaded,
    pairing_section,
)
from acs_cli.stages.joint import read_joint

__all__ = [
    "DEFAULT_EULER",
    "OUTPUT_NAMES",
    "TrajectoryConfig",
    "TrajectoryRun",
    "pair_angles",
    "read_relpose",
    "recover_from_relpose",
    "rig_angles",
    "run_trajectory",
    "zero_index",
]

#: Files ``run_trajectory`` writes into its output folder.
OUTPUT_NAMES = {
    "cam_a": "cam_a.tum",
    "cam_b": "cam_b.tum",
    "joint": "joint.tum",
    "angles": "angles.csv",
    "artifact": "trajectory.yaml",
}


#: The Euler sequence of a ball joint's angles unless the user gives another.
DEFAULT_EULER = "ZXY"


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
    euler : str
        The Euler sequence of a ball joint's angles in ``angles.csv``
        (:data:`acs_cli.core.angles.EULER_SEQUENCES`).
    zero_at : float, optional
        The time (camera A's clock, seconds or frame numbers as its trajectory has them) at
        whose nearest frame the angles are zero; default: the reference instant.
    """

    format_a: str = "auto"
    format_b: str = "auto"
    pair_by: str = "auto"
    max_dt: float | None = None
    euler: str = DEFAULT_EULER
    zero_at: float | None = None


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
    joint_type : str
        ``ball`` or ``hinge``.
    axis_in_a : ndarray (3,) or None
        A hinge's axis in A's frame.
    """

    trajectory: AcsTrajectory
    pair: PairedTrajectories
    rejected: np.ndarray
    joint_source: str
    position_in_a: np.ndarray
    position_in_b: np.ndarray
    length_unit: str
    mu_a: float | None
    joint_type: str = "ball"
    axis_in_a: np.ndarray | None = None


TrajectoryRun = StageRun[RecoveredTrajectory]


def read_relpose(path: Path) -> RelposeArtifact:
    """A ``relpose.yaml`` with the joint in both cameras (``InputError`` otherwise)."""
    art = RelposeArtifact.load(path)
    art.require_joint()
    return art


def _reference_index(relpose: RelposeArtifact, pair: PairedTrajectories) -> int:
    """The paired frame at ``relpose.yaml``'s reference instant (by timestamps when known)."""
    rel = relpose.relative_pose
    path = relpose.source
    ta, tb = rel.reference_timestamp_a, rel.reference_timestamp_b
    if ta is None or tb is None:
        k = rel.reference
        if not 0 <= k < len(pair.a):
            raise InputError(
                f"relative_pose.reference = {k!r} is not one of the {len(pair.a)} paired frames",
                path=path,
            )
        return int(k)
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


def recover_from_relpose(
    relpose: RelposeArtifact,
    pair: PairedTrajectories,
    joint_path: Path | None = None,
) -> RecoveredTrajectory:
    """The ACS's trajectory from a read ``relpose.yaml`` and the paired trajectories.

    Parameters
    ----------
    relpose : RelposeArtifact
        From :func:`read_relpose` (its ``source`` is named in messages).
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
    relpose_path = relpose.source
    joint = relpose.require_joint()
    scale = relpose.scale
    mu_a = None if scale is None else scale.mu_a
    mu_b = None if scale is None else scale.mu_b
    section = joint
    if joint_path is None:
        o_a, o_b = joint.position_in_a, joint.position_in_b
        if o_b is None:  # require_joint refuses this; the check keeps o_b's type
            raise InputError("missing key 'joint.position_in_b'", path=relpose_path)
        source = f"{relpose_path} (joint estimated with the relative pose)"
    else:
        given = read_joint(joint_path)
        if given.position_in_b is None:
            raise InputError(
                "has no joint.position_in_b: the trajectory needs the joint in both cameras "
                "(or leave out --joint to use relpose.yaml's joint)",
                path=joint_path,
            )
        o_a, o_b = given.position_in_a, given.position_in_b
        section = given
        source = str(joint_path)
        if mu_a is not None and mu_b is not None:
            o_a, o_b = o_a * mu_a, o_b * mu_b
            source += " (metric, scaled by mu_a and mu_b of relpose.yaml)"
    k = _reference_index(relpose, pair)
    try:
        traj = recover_trajectory(
            pair.a.T_world_cam,
            pair.b.T_world_cam,
            relpose.relative_pose.T_b_a,
            o_a,
            o_b,
            reference=k,
            phi_ba=relpose.phi_ba,
        )
    except InputError as exc:
        raise InputError(exc.message, path=relpose_path) from exc
    length_unit = "A units" if relpose.unknown_scale else relpose.length_unit
    rejected = relpose.quality.frames.mask(pair.a.timestamps)
    jtype = section.type or "ball"
    axis = None if section.axis_in_a is None else np.asarray(section.axis_in_a, dtype=float)
    return RecoveredTrajectory(
        traj, pair, rejected, source, o_a, o_b, length_unit, mu_a, jtype, axis
    )


def _check_inputs_match(
    relpose: RelposeArtifact, poses: tuple[PosesArtifact, PosesArtifact]
) -> list[str]:
    """Warnings when the trajectories are not the ones ``relpose.yaml`` was made from."""
    warnings: list[str] = []
    for role, given in zip(("poses_a", "poses_b"), poses, strict=True):
        rec = relpose.inputs.get(role)
        if isinstance(rec, dict) and rec.get("sha256") and rec["sha256"] != given.sha256:
            warnings.append(
                f"{given.source} differs from the {role} relpose.yaml was estimated from "
                f"({rec.get('path')})"
            )
    return warnings


def zero_index(times: np.ndarray, zero_at: float | None, default: int) -> int:
    """The frame of ``times`` ``(n,)`` (sorted) nearest ``zero_at``, where a joint's angles
    are zero; ``default`` when it is None.

    Raises
    ------
    InputError
        ``zero_at`` lies outside the frames' span by more than their median spacing.
    """
    if zero_at is None:
        return default
    t = np.asarray(times, dtype=float)
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    if not (np.isfinite(zero_at) and t[0] - step <= zero_at <= t[-1] + step):
        raise InputError(
            f"--zero-at {zero_at:g}: no frame near it (the frames run from {t[0]:g} to {t[-1]:g})"
        )
    return int(np.argmin(np.abs(t - zero_at)))


def pair_angles(
    rec: RecoveredTrajectory, relpose: RelposeArtifact, euler: str, zero: int | None = None
) -> HingeAngles | BallAngles:
    """The joint's angles per paired frame (B relative to A since frame ``zero``, by default
    the reference instant): a hinge's about its axis in A, a ball's as a rotation vector and
    Euler angles; stds from ``relpose.yaml``'s estimated rotation noise of each camera (NaN
    when it has none)."""
    traj = rec.trajectory
    k = traj.reference if zero is None else zero
    D = articulation_from_orientations(traj.T_r_a[:, :3, :3], traj.T_r_b[:, :3, :3], k)
    noise = relpose.quality.estimated_pose_noise
    sigma = float("nan") if noise is None else float(noise.sigma_rot_deg)
    if rec.joint_type == "hinge" and rec.axis_in_a is not None:
        return hinge_angles(D, rec.axis_in_a, sigma, k)
    return ball_angles(D, sigma, k, euler)


def angles_section(
    angles: HingeAngles | BallAngles, rec: RecoveredTrajectory, zero: int
) -> dict[str, Any]:
    """``trajectory.yaml``'s ``angles``: what ``angles.csv`` holds and its zero (frame
    ``zero``)."""
    pair, k = rec.pair, zero
    body: dict[str, Any] = {
        "file": OUTPUT_NAMES["angles"],
        "joint_type": rec.joint_type if isinstance(angles, HingeAngles) else "ball",
        "zero": {"index": k, "timestamp_a": float(pair.a.timestamps[k])},
        "std_from": "the poses' rotation noise of each camera "
        "(quality.estimated_pose_noise of relpose.yaml); the calibration enters at second order",
    }
    if isinstance(angles, HingeAngles):
        body["axis_in_a"] = None if rec.axis_in_a is None else rec.axis_in_a.tolist()
        body["wobble_rms_deg"] = angles.wobble_rms_deg
        body["angle_range_deg"] = [float(angles.angle_deg.min()), float(angles.angle_deg.max())]
    else:
        body["euler_sequence"] = angles.sequence
    return body


def rig_angles(
    rig: RigArtifact,
    paths: dict[str, tuple[np.ndarray, FloatArray]],
    euler: str = DEFAULT_EULER,
    zero_at: float | None = None,
) -> list[JointAngleSeries]:
    """Each ball and hinge joint's angles over the instants both its bodies have a pose
    (``paths``: :func:`acs_cli.stages.rig.trajectories_from_rig`), zero at the instant
    nearest ``zero_at`` (:func:`zero_index`; default: the reference camera's reference
    frame). A hinge's std comes from its own
    off-axis wobble (on a true hinge the wobble is the relative rotation noise across the
    axis, which the angle carries along it: ``std^2 = mean(wobble^2) / 2``); a ball joint's
    from its two bodies' rotation noise as the rig's solve fitted it (``rig.yaml``'s
    ``cameras.<c>.sigma_rotation_deg``), empty where a body has none (its joints do not tell
    it, or a ``rig.yaml`` older than it)."""
    series: list[JointAngleSeries] = []
    ref_times = paths[rig.reference_camera][0] if rig.reference_camera in paths else None
    for name, j in rig.joints.items():
        p, q = j.between
        if j.type not in ("ball", "hinge") or p not in paths or q not in paths:
            continue
        (tp, Tp), (tq, Tq) = paths[p], paths[q]
        common, ip, iq = np.intersect1d(tp, tq, assume_unique=True, return_indices=True)
        if common.size < 2:
            continue
        t0 = (
            common[0]
            if ref_times is None
            else ref_times[min(rig.reference_frame, ref_times.size - 1)]
        )
        k = zero_index(common, zero_at, int(np.argmin(np.abs(common - t0))))
        D = articulation_from_orientations(Tp[ip, :3, :3], Tq[iq, :3, :3], k)
        angles: HingeAngles | BallAngles
        if j.type == "hinge" and p in j.axis_in:
            h = hinge_angles(D, j.axis_in[p], float("nan"), k)
            others = np.arange(common.size) != k
            sigma = float(np.sqrt(np.mean(h.wobble_deg[others] ** 2) / 8.0))
            std = np.where(others, 2.0 * sigma, 0.0)
            angles = HingeAngles(h.angle_deg, std, h.wobble_deg)
        else:
            # each body's rotation noise: D carries both bodies' (module acs_cli.core.angles)
            sp, sq = (rig.cameras[c].sigma_rotation_deg for c in (p, q))
            sigma = (
                float("nan") if sp is None or sq is None else float(np.hypot(sp, sq) / np.sqrt(2))
            )
            angles = ball_angles(D, sigma, k, euler)
        series.append(JointAngleSeries(name, common, angles, k))
    return series


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
    check_euler_sequence(cfg.euler, "--euler ")  # before anything is written
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError("is a file; -o takes a folder for the trajectory files", path=out_dir)
    pa, pb = PosesArtifact.load(poses_a, cfg.format_a), PosesArtifact.load(poses_b, cfg.format_b)
    inputs: dict[str, Path | PosesArtifact] = {"relpose": relpose, "poses_a": pa, "poses_b": pb}
    if joint is not None:
        inputs["joint"] = joint
    outputs = {key: out_dir / name for key, name in OUTPUT_NAMES.items()}
    for out in outputs.values():
        check_distinct_output(out, input_files(inputs))
    for out in outputs.values():  # all of them before the first is replaced
        check_writable(out)
    art = read_relpose(relpose)
    pair_by, max_dt = cfg.pair_by, cfg.max_dt
    recorded = art.quality.pairing
    if pair_by == "auto" and max_dt is None and recorded is not None:
        pair_by, max_dt = recorded.pair_by, recorded.max_dt_s
    pair = pair_loaded(pa.trajectory, pb.trajectory, pair_by, max_dt)
    rec = recover_from_relpose(art, pair, joint)
    warnings = list(pair.warnings) + _check_inputs_match(art, (pa, pb))
    traj = rec.trajectory
    n_rej = int(rec.rejected.sum())
    if n_rej:
        warnings.append(f"{n_rej} frame(s) were rejected as outliers by relpose (marked)")
    marks = weak_marks(relpose.name, art.verdict)
    warnings += marks
    zero = zero_index(pair.a.timestamps, cfg.zero_at, traj.reference)  # before any write

    for key, times, T in (
        ("cam_a", pair.a, traj.T_r_a),
        ("cam_b", pair.b, traj.T_r_b),
        ("joint", pair.a, traj.T_r_joint),
    ):
        notes = marks + ([] if times.time_unit == "s" else [f"{FRAME_NUMBERS_NOTE}, not seconds"])
        note = "; ".join(notes) or None
        write_tum(outputs[key], times.timestamps, T, timestamps_ns=times.timestamps_ns, note=note)

    angles = pair_angles(rec, art, cfg.euler, zero)
    write_angles_csv(
        outputs["angles"], [JointAngleSeries("joint", pair.a.timestamps, angles, zero)]
    )
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
            if art.unknown_scale
            else "none (known scale)",
            "mu_a": rec.mu_a,
        },
        "joint": {
            "source": rec.joint_source,
            "position_in_a": rec.position_in_a.tolist(),
            "position_in_b": rec.position_in_b.tolist(),
        },
        "outputs": {key: name for key, name in OUTPUT_NAMES.items() if key != "artifact"},
        "angles": angles_section(angles, rec, zero),
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
        "quality": {"pairing": pairing_section(pair.pairing, pair_by).to_plain()},
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
            if art.unknown_scale
            else rec.length_unit,
            "timestamps": "s (or frame numbers for trajectories without timestamps)",
            "angles": "deg",
            "position_in_b": "B units" if art.unknown_scale else rec.length_unit,
        },
        frames={
            "world": "the frame of A's poses at the reference instant (camera A's optical "
            "frame; a body's own frame when A's poses are a body's)",
            "cam_a.tum": "T_world_a: A's pose (camera or body)",
            "cam_b.tum": "T_world_b: B's pose (camera or body)",
            "joint.tum": "T_world_joint: the joint (as camera A sees it), camera A's orientation",
            "consistency.frames.distance": "|joint from A - joint from B| in the world frame",
            "angles.csv": "B turning relative to A since the reference instant: a hinge's "
            "angle about angles.axis_in_a (right-hand rule); a ball's rotation vector and "
            "Euler angles in A's frame",
        },
    )
    write_yaml_artifact(outputs["artifact"], header, body)
    return StageRun(rec, header | body, outputs["artifact"], warnings)
