"""The joint stage: ``acscal joint`` (Algorithms I and II)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.core.bundle import (
    INTRINSIC_NAMES,
    bundle_adjust_fixed_joint,
    camera_matrix,
    intrinsics_vector,
)
from acs_cli.core.joint import JointEstimate, estimate_joint_fixed, estimate_joint_overlap
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header, read_yaml_artifact, write_yaml_artifact
from acs_cli.io.atomic import check_distinct_output
from acs_cli.io.trajectory import read_npz_observations
from acs_cli.stages.common import (
    StageRun,
    frames_section,
    load_pair,
    load_trajectory,
    pairing_section,
    vector_with_std,
)
from acs_cli.stages.poses import read_intrinsics

SCENARIOS = ("fixed_joint", "overlap")

METHOD_TEXT = {
    ("fixed_joint", "paper"): "Algorithm II (Chen & Wong eq. (12)): linear least squares of "
    "(R^i - I) O = -T^i relative to the first frame",
    ("fixed_joint", "refined"): "fixed joint, world joint position unknown; frames weighted by "
    "the pose noise they carry (levels estimated), outliers rejected",
    ("overlap", "paper"): "Algorithm I (Chen & Wong eq. (9)): linear least squares",
    ("overlap", "refined"): "Algorithm I's constraint weighted by the pose noise (levels "
    "estimated), outliers rejected",
}


@dataclass(frozen=True)
class JointConfig:
    """Options of the joint stage.

    Attributes
    ----------
    scenario : {"fixed_joint", "overlap"}
    method : {"refined", "paper"}
    format_a, format_b : str
        Trajectory file formats (``auto`` sniffs).
    pair_by : {"auto", "timestamp", "index"}
        Overlap only: how A's and B's samples are paired.
    max_dt : float, optional
        Largest timestamp difference of a pair, seconds.
    length_unit : str
        The unit of the trajectories' translations, recorded in the artifact.
    bundle : bool
        Fixed joint, refined: when a poses NPZ carries its corners (``acscal poses``),
        refine that camera's joint and intrinsics by bundle adjustment on them.
    """

    scenario: str = "fixed_joint"
    method: str = "refined"
    format_a: str = "auto"
    format_b: str = "auto"
    pair_by: str = "auto"
    max_dt: float | None = None
    length_unit: str = "m"
    bundle: bool = False


JointRun = StageRun[JointEstimate]


def joint_body(est: JointEstimate, length_unit: str) -> dict[str, Any]:
    """The ``joint`` section of an artifact from an estimate."""
    pa, sa = vector_with_std(est.position_in_a, est.covariance_a)
    body: dict[str, Any] = {"position_in_a": pa, "position_in_a_std": sa}
    if est.position_in_b is not None:
        pb, sb = vector_with_std(est.position_in_b, est.covariance_b)
        body |= {"position_in_b": pb, "position_in_b_std": sb}
    body["covariance_a"] = est.covariance_a.tolist()
    if est.covariance_b is not None:
        body["covariance_b"] = est.covariance_b.tolist()
    body["units"] = length_unit
    return body


def _resolve_intrinsics(recorded: str, poses: Path) -> Path | None:
    """The intrinsics file a poses NPZ names: as recorded, or beside the NPZ."""
    for candidate in (Path(recorded), poses.parent / Path(recorded).name):
        if candidate.is_file():
            return candidate
    return None


def _bundle(
    poses: Path, T_w_c: np.ndarray, est: JointEstimate, cam: str
) -> tuple[JointEstimate, dict[str, Any] | None, str | None]:
    """Refine camera ``cam``'s joint (and intrinsics) on its corners, when they are there.

    Returns the (possibly) refined estimate, the artifact's ``bundle`` section and a warning.
    """
    obs = read_npz_observations(poses) if poses.suffix.lower() == ".npz" else None
    if obs is None:
        return est, None, None
    if obs.corners.shape[0] != T_w_c.shape[0]:
        return est, None, f"{poses.name}: corners and poses disagree; bundle adjustment skipped"
    intr_path = (
        None if obs.intrinsics_file is None else _resolve_intrinsics(obs.intrinsics_file, poses)
    )
    if intr_path is None:
        return est, None, f"{poses.name}: its intrinsics file was not found; no bundle adjustment"
    intr = read_intrinsics(intr_path)
    if intr.model != "pinhole":
        return est, None, f"bundle adjustment supports the pinhole model, not {intr.model}"
    inl = est.inliers[cam]
    o0 = est.position_in_a if cam == "a" else est.position_in_b
    if o0 is None:
        return est, None, None
    ba = bundle_adjust_fixed_joint(
        obs.corners[inl],
        np.ones(obs.corners[inl].shape[:2], dtype=bool),
        obs.board_points,
        intrinsics_vector(intr.camera_matrix, intr.distortion),
        T_w_c[inl],
        o0,
        est.position_in_world[cam],
    )
    cov = ba.covariance[9:12, 9:12]
    refined = (
        replace(est, position_in_a=ba.joint_in_cam, covariance_a=cov)
        if cam == "a"
        else replace(est, position_in_b=ba.joint_in_cam, covariance_b=cov)
    )
    refined.position_in_world[cam] = ba.joint_in_world
    section = {
        "intrinsics_file": str(intr_path),
        "rms_px": ba.rms_px,
        "sigma_px": ba.sigma_px,
        "frames": int(inl.sum()),
        "camera_matrix": camera_matrix(ba.intrinsics).tolist(),
        "distortion": ba.intrinsics[4:].tolist(),
        "intrinsics_std": dict(
            zip(INTRINSIC_NAMES, np.sqrt(np.diag(ba.covariance)[:9]).tolist(), strict=True)
        ),
        "converged": ba.success,
    }
    return refined, section, None


def run_joint(poses_a: Path, poses_b: Path | None, output: Path, config: JointConfig) -> JointRun:
    """Read the trajectories, estimate the joint and write ``joint.yaml`` atomically.

    Raises
    ------
    InputError
        Bad files or options.
    DegenerateMotionError
        The motion cannot determine the joint (nothing is written).
    """
    if config.scenario not in SCENARIOS:
        raise InputError(f"unknown scenario {config.scenario!r}")
    inputs = {"poses_a": poses_a} | ({"poses_b": poses_b} if poses_b is not None else {})
    check_distinct_output(output, inputs.values())
    warnings: list[str] = []
    quality: dict[str, Any] = {}
    if config.scenario == "overlap":
        if poses_b is None:
            raise InputError("--overlap needs both --poses-a and --poses-b")
        pair = load_pair(
            poses_a, poses_b, config.format_a, config.format_b, config.pair_by, config.max_dt
        )
        warnings += pair.warnings
        est = estimate_joint_overlap(pair.a.T_world_cam, pair.b.T_world_cam, config.method)
        quality["pairing"] = pairing_section(pair.pairing, config.pair_by)
        quality["frames"] = {"ab": frames_section(est.inliers["ab"], pair.a.timestamps)}
    else:
        ta = load_trajectory(poses_a, config.format_a)
        tb = None if poses_b is None else load_trajectory(poses_b, config.format_b)
        est = estimate_joint_fixed(
            ta.T_world_cam, None if tb is None else tb.T_world_cam, config.method
        )
        if config.method == "refined" and config.bundle:
            bundles: dict[str, Any] = {}
            for cam, path, traj in (("a", poses_a, ta), ("b", poses_b, tb)):
                if path is None or traj is None:
                    continue
                est, section, warning = _bundle(path, traj.T_world_cam, est, cam)
                if section is not None:
                    bundles[cam] = section
                if warning is not None:
                    warnings.append(warning)
            if bundles:
                quality["bundle_adjustment"] = bundles
        quality["frames"] = {"a": frames_section(est.inliers["a"], ta.timestamps)}
        if tb is not None:
            quality["frames"]["b"] = frames_section(est.inliers["b"], tb.timestamps)
        quality["joint_in_world"] = {k: v.tolist() for k, v in est.position_in_world.items()}
    for key, fr in quality["frames"].items():
        if fr["rejected"]:
            warnings.append(
                f"{len(fr['rejected'])} frame(s) of {key.upper()} rejected as outliers "
                f"(timestamps {fr['rejected'][:10]})"
            )
    quality["residual_rms"] = est.residual_rms
    if est.noise:
        quality["estimated_pose_noise"] = est.noise
    header = make_header(
        "joint",
        inputs,
        method=f"{config.method}: {METHOD_TEXT[(config.scenario, config.method)]}"
        + (
            "; then a bundle adjustment on the detected corners (intrinsics, joint and "
            "per-frame rotations) for the cameras listed in quality.bundle_adjustment"
            if "bundle_adjustment" in quality
            else ""
        ),
        units={"length": config.length_unit, "angles": "deg"},
        frames={
            "position_in_a": "camera A's optical frame",
            "position_in_b": "camera B's optical frame",
            "joint_in_world": "each trajectory's own world frame (fixed joint only)",
        },
    )
    body = {
        "scenario": config.scenario,
        "joint": joint_body(est, config.length_unit),
        "quality": quality,
        "warnings": warnings,
    }
    write_yaml_artifact(output, header, body)
    return StageRun(est, header | body, output, warnings)


def read_joint(path: Path) -> dict[str, Any]:
    """Read a ``joint.yaml`` (or a ``relpose.yaml`` holding a joint): its ``joint`` section."""
    try:
        doc = read_yaml_artifact(path, "joint", ["joint.position_in_a"])
    except InputError as exc:
        if "acscal/relpose" not in exc.message:
            raise
        doc = read_yaml_artifact(path, "relpose", ["joint.position_in_a"])
    joint = doc["joint"]
    if not isinstance(joint, dict):
        raise InputError("'joint' must be a mapping", path=path)
    return joint
