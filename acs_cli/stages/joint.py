"""The joint stage: ``acscal joint`` (Algorithms I and II)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from acs_cli.core.joint import JointEstimate, estimate_joint_fixed, estimate_joint_overlap
from acs_cli.errors import DegenerateMotionError, InputError
from acs_cli.io.artifacts import make_header, to_plain
from acs_cli.io.atomic import check_distinct_output, check_writable
from acs_cli.io.joint import (
    BundleSection,
    FramesUsed,
    JointArtifact,
    JointQuality,
    JointSection,
    Pairing,
    PoseNoise,
    load_joint_section,
)
from acs_cli.stages.bundle import bundle_fixed_joint, bundle_overlap, shared_board_flip
from acs_cli.stages.common import (
    PairedTrajectories,
    StageRun,
    load_pair,
    load_trajectory,
    pairing_section,
)

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
        Refined method: when the poses NPZs carry their corners (``acscal poses``), refine
        the joint and the intrinsics by bundle adjustment on them (per camera for the fixed
        joint, both cameras together for the overlap). Trajectories without corners are
        used as they are.
    """

    scenario: str = "fixed_joint"
    method: str = "refined"
    format_a: str = "auto"
    format_b: str = "auto"
    pair_by: str = "auto"
    max_dt: float | None = None
    length_unit: str = "m"
    bundle: bool = True


JointRun = StageRun[JointEstimate]


def joint_section(est: JointEstimate, length_unit: str) -> JointSection:
    """The ``joint`` section of an artifact from an estimate."""
    return JointSection.from_estimate(
        est.position_in_a, est.covariance_a, est.position_in_b, est.covariance_b, units=length_unit
    )


def _overlap_in_one_board_order(
    pair: PairedTrajectories, poses: tuple[Path, Path], method: str
) -> tuple[JointEstimate, PairedTrajectories, bool]:
    """Algorithm I, with B's board labelling turned to A's when that is what fits.

    Two cameras of an overlap rig can label the shared board in its two orders (see
    :func:`acs_cli.stages.bundle.shared_board_flip`); then the worlds differ by a half turn
    and the joint constraint fits badly or looks degenerate. Both labellings are tried
    when the poses carry their board; the turned one wins when its residual is less than
    half the other's (the wrong one is off by the board's size, not by noise). A pair that
    looks rigid as labelled is reported as such: turning a rigid pair's frame invents an
    articulation (seen on OpenCV's stereo photographs: a 5 cm residual and "6 deg" of
    rotation noise).
    """
    est0: JointEstimate | None = None
    error: DegenerateMotionError | None = None
    try:
        est0 = estimate_joint_overlap(pair.a.T_world_cam, pair.b.T_world_cam, method)
    except DegenerateMotionError as exc:
        error = exc
    F = shared_board_flip(poses)
    if F is not None:
        turned = replace(pair, b=replace(pair.b, T_world_cam=F @ pair.b.T_world_cam))
        try:
            est1 = estimate_joint_overlap(turned.a.T_world_cam, turned.b.T_world_cam, method)
        except DegenerateMotionError as exc:
            est1 = None
            if est0 is not None and _rigid_spread(turned) < 0.5 * est0.residual_rms["ab"]:
                # turned, the pair is rigid (fits to noise); as labelled, its "joint" only
                # absorbs the half turn: a rigid pair labelled in opposite orders
                raise DegenerateMotionError(
                    exc.message + " (the two cameras labelled the shared board in opposite "
                    "orders; turned to one order, they move rigidly together)",
                    details=exc.details,
                ) from None
        # a rigid-looking pair (est0 degenerate) is trusted as it is: turning one camera's
        # board frame of a rigid pair makes a spurious articulation, not a better fit
        if (
            est0 is not None
            and est1 is not None
            and est1.residual_rms["ab"] < 0.5 * est0.residual_rms["ab"]
        ):
            return est1, turned, True
    if est0 is None:
        raise error if error is not None else DegenerateMotionError("the joint cannot be observed")
    return est0, pair, False


def _rigid_spread(pair: PairedTrajectories) -> float:
    """RMS spread of B's position in A's frame over the frames (0 for a rigid pair)."""
    T_a_b = np.matmul(np.linalg.inv(pair.a.T_world_cam), pair.b.T_world_cam)
    t = T_a_b[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum((t - t.mean(axis=0)) ** 2, axis=1))))


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
    check_writable(output)
    warnings: list[str] = []
    bundles: dict[str, BundleSection] = {}
    pairing: Pairing | None = None
    frames: dict[str, FramesUsed] = {}
    in_world: dict[str, np.ndarray] = {}
    if config.scenario == "overlap":
        if poses_b is None:
            raise InputError("--overlap needs both --poses-a and --poses-b")
        pair = load_pair(
            poses_a, poses_b, config.format_a, config.format_b, config.pair_by, config.max_dt
        )
        warnings += pair.warnings
        est, pair, turned = _overlap_in_one_board_order(pair, (poses_a, poses_b), config.method)
        if turned:
            warnings.append(
                "the two cameras labelled the shared board in opposite orders (their rolls "
                "differ by more than 90 degrees); B's poses were turned to A's board frame"
            )
        if config.method == "refined" and config.bundle:
            est, sections, notes = bundle_overlap((poses_a, poses_b), pair, est, turned)
            warnings += notes
            bundles = sections or {}
        pairing = pairing_section(pair.pairing, config.pair_by)
        frames["ab"] = FramesUsed.from_inliers(est.inliers["ab"], pair.a.timestamps)
    else:
        ta = load_trajectory(poses_a, config.format_a)
        tb = None if poses_b is None else load_trajectory(poses_b, config.format_b)
        est = estimate_joint_fixed(
            ta.T_world_cam, None if tb is None else tb.T_world_cam, config.method
        )
        if config.method == "refined" and config.bundle:
            for cam, path, traj in (("a", poses_a, ta), ("b", poses_b, tb)):
                if path is None or traj is None:
                    continue
                est, section, notes = bundle_fixed_joint(path, traj.T_world_cam, est, cam)
                if section is not None:
                    bundles[cam] = section
                warnings += notes
        frames["a"] = FramesUsed.from_inliers(est.inliers["a"], ta.timestamps)
        if tb is not None:
            frames["b"] = FramesUsed.from_inliers(est.inliers["b"], tb.timestamps)
        in_world = {k: np.asarray(v, dtype=float) for k, v in est.position_in_world.items()}
    for key, fr in frames.items():
        if fr.rejected:
            warnings.append(
                f"{len(fr.rejected)} frame(s) of {key.upper()} rejected as outliers "
                f"(timestamps {fr.rejected[:10]})"
            )
    quality = JointQuality(
        frames=frames,
        residual_rms=dict(est.residual_rms),
        pairing=pairing,
        joint_in_world=in_world,
        estimated_pose_noise={
            k: PoseNoise(float(v["sigma_trans"]), float(v["sigma_rot_deg"]))
            for k, v in est.noise.items()
        },
        bundle_adjustment=bundles,
    )
    header = make_header(
        "joint",
        inputs,
        method=f"{config.method}: {METHOD_TEXT[(config.scenario, config.method)]}"
        + (
            "; then a bundle adjustment on the detected corners (intrinsics, joint and "
            "per-frame rotations; overlap: both cameras together) for the cameras listed in "
            "quality.bundle_adjustment"
            if bundles
            else ""
        ),
        units={"length": config.length_unit, "angles": "deg"},
        frames={
            "position_in_a": "camera A's optical frame",
            "position_in_b": "camera B's optical frame",
            "joint_in_world": "each trajectory's own world frame (fixed joint only)",
        },
    )
    art = JointArtifact(
        scenario=config.scenario,
        joint=joint_section(est, config.length_unit),
        quality=quality,
        warnings=warnings,
        header=header,
        source=str(output),
    )
    art.save(output)
    return StageRun(est, to_plain(art.to_doc()), output, warnings)


def read_joint(path: Path) -> JointSection:
    """The joint of a ``joint.yaml`` (or of a ``relpose.yaml``), checked
    (:func:`acs_cli.io.joint.load_joint_section`)."""
    return load_joint_section(path)
