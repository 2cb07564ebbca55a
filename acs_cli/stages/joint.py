"""The joint stage: ``acscal joint`` (Algorithms I and II)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.core.diagnose import (
    Diagnosis,
    TimedPair,
    diagnose_fixed_joint,
    diagnose_overlap,
    fit_is_suspicious,
    paper_method_misfit,
)
from acs_cli.core.joint import (
    JointEstimate,
    estimate_joint_fixed,
    estimate_pivot,
    joint_motion_warnings,
    overlap_motion,
)
from acs_cli.core.overlap import (
    OVERLAP_RIG,
    check_overlap_joint_type,
    estimate_joint_overlap,
    estimate_overlap_rig,
    joint_of_rig,
    overlap_tracks,
)
from acs_cli.core.paper import algorithm_1_overlap, algorithm_2_fixed_joint
from acs_cli.core.quality import Measure, joint_measures, judge, length_scale
from acs_cli.core.relpose import in_pair_words
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import AcsError, DegenerateMotionError, InputError
from acs_cli.io.artifacts import make_header, to_plain
from acs_cli.io.atomic import check_distinct_output, check_writable
from acs_cli.io.joint import (
    BundleSection,
    FramesUsed,
    JointArtifact,
    JointQuality,
    JointSection,
    MotionQuality,
    Pairing,
    PoseNoise,
    UncertaintySection,
)
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.relpose import RelposeArtifact, load_joint_artifact, load_joint_section
from acs_cli.io.trajectory import Trajectory
from acs_cli.io.verdict import VerdictSection
from acs_cli.stages.bundle import (
    board_order_residuals,
    bundle_fixed_joint,
    bundle_overlap,
    shared_board_flip,
)
from acs_cli.stages.common import (
    PairedTrajectories,
    StageRun,
    input_files,
    load_poses,
    pair_loaded,
    pairing_section,
)

SCENARIOS = ("fixed_joint", "overlap")

METHOD_TEXT = {
    ("fixed_joint", "paper"): "Algorithm II (Chen & Wong eq. (12)): linear least squares of "
    "(R^i - I) O = -T^i relative to the first frame",
    ("fixed_joint", "refined"): "fixed joint, world joint position unknown; frames weighted by "
    "the pose noise they carry (levels estimated), outliers rejected",
    ("overlap", "paper"): "Algorithm I (Chen & Wong eq. (9)): linear least squares",
    ("overlap", "refined"): "Algorithm I as a two-body rig in one world (the rig engine): "
    "the constraint weighted by the pose noise (levels estimated), outliers rejected",
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
    accept_weak : bool
        Write a result past a refusal level of :mod:`acs_cli.core.quality` anyway, marked
        weak (``--accept-weak``).
    joint_type : {"ball", "hinge"}
        Overlap, refined method: the two-body rig's joint (``--joint-type``). A hinge is
        written with its axis in each camera (``joint.axis_in_a``, ...); a rigid pair has
        no joint point to locate and is refused.
    """

    scenario: str = "fixed_joint"
    method: str = "refined"
    format_a: str = "auto"
    format_b: str = "auto"
    pair_by: str = "auto"
    max_dt: float | None = None
    length_unit: str = "m"
    bundle: bool = True
    accept_weak: bool = False
    joint_type: str = "ball"


JointRun = StageRun[JointEstimate]


def joint_section(est: JointEstimate, length_unit: str) -> JointSection:
    """The ``joint`` section of an artifact from an estimate (a hinge's with its axes)."""
    return JointSection.from_estimate(
        est.position_in_a, est.covariance_a, est.position_in_b, est.covariance_b, units=length_unit
    ).with_axes(est.joint_type, est.axis_in, est.axis_std_deg_in)


def _in_one_board_order(
    pair: PairedTrajectories, F: np.ndarray | None
) -> tuple[PairedTrajectories, bool]:
    """The pair with B's board labelling turned to A's when that is what fits.

    Two cameras of an overlap rig can label the shared board in its two orders (``F``:
    :func:`acs_cli.stages.bundle.shared_board_flip`, None when the poses do not carry one
    symmetric board); then the worlds differ by a half turn and the joint fits badly or
    looks degenerate. The turned labelling wins when its joint fits with less than half the
    residual (:func:`acs_cli.stages.bundle.board_order_residuals`, as ``acscal run`` does for
    a rig). A pair that is rigid (or a hinge) as labelled is trusted as it is: turning one
    camera's board frame of a rigid pair invents an articulation. A pair that moves rigidly
    once turned is refused as such (seen on OpenCV's stereo photographs: a 5 cm residual and
    "6 deg" of rotation noise as labelled).

    Raises
    ------
    DegenerateMotionError
        Turned to one labelling, the two cameras move rigidly together.
    """
    if F is None:
        return pair, False
    turned = replace(pair, b=replace(pair.b, T_world_cam=F @ pair.b.T_world_cam))
    try:
        overlap_motion(pair.a.T_world_cam, pair.b.T_world_cam)
    except DegenerateMotionError:
        return pair, False
    tracks = overlap_tracks(pair.a.T_world_cam, pair.b.T_world_cam)
    rms0, rms1 = board_order_residuals(OVERLAP_RIG.joints[0], "a", tracks, F)
    if rms1 < 0.5 * rms0:
        return turned, True
    try:
        overlap_motion(turned.a.T_world_cam, turned.b.T_world_cam)
    except DegenerateMotionError as exc:
        if "rotation_spread_deg" in exc.details:  # turned, a rigid pair
            raise DegenerateMotionError(
                exc.message + " (the two cameras labelled the shared board in opposite "
                "orders; turned to one order, they move rigidly together)",
                details=exc.details,
            ) from None
    return pair, False


def run_joint(
    poses_a: Path | PosesArtifact,
    poses_b: Path | PosesArtifact | None,
    output: Path,
    config: JointConfig,
) -> JointRun:
    """Read the trajectories (each once, unless given read), estimate the joint and write
    ``joint.yaml`` atomically.

    Raises
    ------
    InputError
        Bad files or options.
    DegenerateMotionError
        The motion cannot determine the joint (nothing is written).
    """
    if config.scenario not in SCENARIOS:
        raise InputError(f"unknown scenario {config.scenario!r}")
    if config.joint_type != "ball" and config.scenario != "overlap":
        raise InputError(
            "--joint-type applies to `joint --overlap` and `relpose`; a fixed-joint session "
            "locates a ball joint (a pivot)"
        )
    check_overlap_joint_type(config.joint_type, config.method)
    pa = load_poses(poses_a, config.format_a)
    pb = None if poses_b is None else load_poses(poses_b, config.format_b)
    inputs = {"poses_a": pa} | ({"poses_b": pb} if pb is not None else {})
    check_distinct_output(output, input_files(inputs))
    check_writable(output)
    warnings: list[str] = []
    bundles: dict[str, BundleSection] = {}
    pairing: Pairing | None = None
    frames: dict[str, FramesUsed] = {}
    in_world: dict[str, np.ndarray] = {}
    poses_by_key: dict[str, np.ndarray] = {}
    if config.scenario == "overlap":
        if pb is None:
            raise InputError("--overlap needs both --poses-a and --poses-b")
        pair = pair_loaded(pa.trajectory, pb.trajectory, config.pair_by, config.max_dt)
        warnings += pair.warnings
        pair, turned = _in_one_board_order(pair, shared_board_flip((pa, pb)))
        if turned:
            warnings.append(
                "the two cameras labelled the shared board in opposite orders (their rolls "
                "differ by more than 90 degrees); B's poses were turned to A's board frame"
            )
        Ta, Tb = pair.a.T_world_cam, pair.b.T_world_cam
        if config.method == "paper":
            est = algorithm_1_overlap(Ta, Tb)
        else:
            rig = estimate_overlap_rig(Ta, Tb, joint_type=config.joint_type)
            warnings += [in_pair_words(w) for w in rig.warnings]  # fits its type poorly
            if config.bundle:
                rig, sections, notes = bundle_overlap((pa, pb), pair, rig, turned)
                warnings += notes
                bundles = sections or {}
            est = joint_of_rig(rig, Ta.shape[0])
        pairing = pairing_section(pair.pairing, config.pair_by)
        frames["ab"] = FramesUsed.from_inliers(est.inliers["ab"], pair.a.timestamps)
        # B's poses in A's frame: the articulation, whose travel sets the overlap's scale
        poses_by_key["ab"] = np.linalg.solve(pair.a.T_world_cam, pair.b.T_world_cam)
    else:
        ta, tb = pa.trajectory, None if pb is None else pb.trajectory
        fixed = algorithm_2_fixed_joint if config.method == "paper" else estimate_joint_fixed
        est = fixed(ta.T_world_cam, None if tb is None else tb.T_world_cam)
        if config.method == "refined" and config.bundle:
            for cam, poses in (("a", pa), ("b", pb)):
                if poses is None:
                    continue
                est, section, notes = bundle_fixed_joint(
                    poses, poses.trajectory.T_world_cam, est, cam
                )
                if section is not None:
                    bundles[cam] = section
                warnings += notes
        frames["a"] = FramesUsed.from_inliers(est.inliers["a"], ta.timestamps)
        poses_by_key["a"] = ta.T_world_cam
        if tb is not None:
            frames["b"] = FramesUsed.from_inliers(est.inliers["b"], tb.timestamps)
            poses_by_key["b"] = tb.T_world_cam
        in_world = {k: np.asarray(v, dtype=float) for k, v in est.position_in_world.items()}
    warnings += joint_motion_warnings(est, config.length_unit)
    for key, fr in frames.items():
        if fr.rejected:
            warnings.append(
                f"{len(fr.rejected)} frame(s) of {key.upper()} rejected as outliers "
                f"(timestamps {fr.rejected[:10]})"
            )
    if config.scenario == "overlap":
        # the diagnosis refits ball joints: a declared hinge is not second-guessed by them
        findings = (
            overlap_findings(est, pair, poses_by_key["ab"], config.length_unit)
            if config.joint_type == "ball"
            else []
        )
    else:
        findings = fixed_joint_findings(est, {"a": ta, "b": tb}, config.length_unit)
    verdict = judge(joint_verdict_measures(est, poses_by_key), config.accept_weak, findings)
    warnings += verdict.warnings()
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
        motion=MotionQuality.of(est.motion, {k: est.covariance_of(k) for k in est.motion}),
        uncertainty={k: UncertaintySection.of(v) for k, v in est.correlated.items()},
    )
    header = make_header(
        "joint",
        inputs,
        method=f"{config.method}: {METHOD_TEXT[(config.scenario, config.method)]}"
        + ("" if config.joint_type == "ball" else f"; the joint declared a {config.joint_type}")
        + (
            "; then a bundle adjustment on the detected corners (intrinsics, joint and "
            "per-frame rotations; overlap: both cameras together) for the cameras listed in "
            "quality.bundle_adjustment"
            if bundles
            else ""
        ),
        units={"length": config.length_unit, "angles": "deg"},
        frames={
            "position_in_a": "the frame of A's poses (camera A's optical frame; a body's own "
            "frame when A's poses are a body's: a mocap segment, a robot flange)",
            "position_in_b": "the frame of B's poses (likewise)",
            "joint_in_world": "each trajectory's own world frame (fixed joint only)",
        },
    )
    art = JointArtifact(
        scenario=config.scenario,
        joint=joint_section(est, config.length_unit),
        quality=quality,
        verdict=VerdictSection.from_verdict(verdict),
        warnings=warnings,
        header=header,
        source=str(output),
    )
    art.save(output)
    return StageRun(est, to_plain(art.to_doc()), output, warnings)


#: Trajectory formats whose rotations are read from quaternions (their order can be wrong).
QUATERNION_FORMATS = ("tum", "colmap")


def timed_pair(pair: PairedTrajectories) -> TimedPair | None:
    """Both paired trajectories with their times, when both are in seconds (for the
    diagnosis' clock check)."""
    a, b = pair.a, pair.b
    if not (a.has_timestamps and b.has_timestamps) or "frame" in (a.time_unit, b.time_unit):
        return None
    return TimedPair(a.timestamps, a.T_world_cam, b.timestamps, b.T_world_cam)


def fixed_joint_findings(
    est: JointEstimate, trajectories: dict[str, Trajectory | None], unit: str
) -> list[str]:
    """What a usual cause explains (:func:`acs_cli.core.diagnose.diagnose_fixed_joint`) for
    each camera whose residual is suspicious against its length scale."""
    out = []
    for key, traj in trajectories.items():
        position = est.position_in_a if key == "a" else est.position_in_b
        rms = est.residual_rms.get(key)
        if traj is None or position is None or rms is None:
            continue
        if not fit_is_suspicious(rms, length_scale(position, traj.T_world_cam)):
            continue
        found = paper_misfit(
            est.method, rms, partial(estimate_pivot, traj.T_world_cam, "refined", key), key, unit
        )
        if found is None:
            found = diagnose_fixed_joint(
                traj.T_world_cam,
                quaternion_source=traj.format in QUATERNION_FORMATS,
                current_rms=rms,
                camera=key,
                unit=unit,
            )
        if found is not None:
            out.append(found.message)
    return out


def paper_misfit(
    method: str, rms: float, refined: Callable[[], Any], key: str, unit: str
) -> Diagnosis | None:
    """With the paper's method: its fit thrown by outliers, when the refined method on the
    same poses (``refined()``, anything with ``residual_rms``: a float, or a dict with
    ``key``) fits much better (:func:`acs_cli.core.diagnose.paper_method_misfit`)."""
    if method != "paper":
        return None
    try:
        got = refined().residual_rms
    except AcsError:
        return None
    rms_refined = float(got[key] if isinstance(got, dict) else got)
    return paper_method_misfit(rms, rms_refined, key, unit)


def overlap_findings(
    est: JointEstimate, pair: PairedTrajectories, T_a_b: FloatArray, unit: str
) -> list[str]:
    """What a usual cause explains (:func:`acs_cli.core.diagnose.diagnose_overlap`) when the
    overlap fit's residual is suspicious against the rig's length scale (``T_a_b`` ``(n, 4,
    4)``: B's poses in A's frame, whose travel sets it)."""
    rms = est.residual_rms.get("ab")
    if rms is None or not fit_is_suspicious(rms, length_scale(est.position_in_a, T_a_b)):
        return []
    found = paper_misfit(
        est.method,
        rms,
        lambda: estimate_joint_overlap(pair.a.T_world_cam, pair.b.T_world_cam, "refined"),
        "ab",
        unit,
    )
    if found is not None:
        return [found.message]
    found = diagnose_overlap(
        pair.a.T_world_cam,
        pair.b.T_world_cam,
        quaternion_source=(
            pair.a.format in QUATERNION_FORMATS,
            pair.b.format in QUATERNION_FORMATS,
        ),
        current_rms=rms,
        timed=timed_pair(pair),
        unit=unit,
    )
    return [] if found is None else [found.message]


def joint_verdict_measures(est: JointEstimate, poses: dict[str, np.ndarray]) -> list[Measure]:
    """The quality measures of a joint estimate (:mod:`acs_cli.core.quality`).

    ``poses`` maps the estimate's keys to the poses that set each length scale: ``a``/``b``
    the cameras' ``T_world_cam`` (fixed joint), ``ab`` B's poses in A's frame (overlap,
    whose residual is in A's frame).
    """
    out: list[Measure] = []
    for key, T in poses.items():
        cam = "a" if key == "ab" else key
        position = est.position_in_a if cam == "a" else est.position_in_b
        cov = est.covariance_a if cam == "a" else est.covariance_b
        if position is None or cov is None:
            continue
        out += joint_measures(
            position,
            cov,
            T,
            est.residual_rms.get(key),
            est.inliers.get(key),
            f"the joint in {cam.upper()}",
            est.joint_type,
        )
    if "ab" in poses and est.position_in_b is not None and est.covariance_b is not None:
        T_b_a = np.linalg.inv(poses["ab"])
        out += joint_measures(
            est.position_in_b, est.covariance_b, T_b_a, None, None, "the joint in B", est.joint_type
        )
    return out


def read_joint(path: Path) -> JointSection:
    """The joint of a ``joint.yaml`` (or of a ``relpose.yaml``), checked
    (:func:`acs_cli.io.relpose.load_joint_section`)."""
    return load_joint_section(path)


def read_joint_in_units(
    path: Path,
    length_unit: str,
    *,
    unknown_scale: bool = False,
    metric: bool = False,
    poses: tuple[PosesArtifact, PosesArtifact] | None = None,
) -> tuple[JointSection, list[str]]:
    """The joint of a ``joint.yaml`` or ``relpose.yaml`` in the unit the trajectories need,
    and the warnings of a conversion.

    The unit needed is ``length_unit`` (known scale), metres (``metric``: ``--joint-metric``
    under unknown scale), or the trajectories' own (unknown scale without ``metric``: not
    checked, as before). A joint in another unit of
    :data:`~acs_cli.io.export.METRES_PER_UNIT` is converted, with a warning; any other
    unit is refused. An unknown-scale ``relpose.yaml``'s joint is in the units of the two
    trajectories it was estimated from (A's for ``position_in_a``, B's for
    ``position_in_b``): it is taken as ``--joint`` only with those same two trajectories
    (``poses``, compared by SHA-256), never as metric.

    Raises
    ------
    InputError
        The joint file is malformed, or its unit cannot be converted to the one needed.
    """
    from acs_cli.io.export import METRES_PER_UNIT

    art = load_joint_artifact(path)
    joint = art.joint
    if joint is None:  # load_joint_artifact refuses this; the check keeps the type
        raise InputError("missing key 'joint.position_in_a'", path=path)
    if isinstance(art, RelposeArtifact) and art.unknown_scale:
        same = poses is not None and all(
            isinstance(rec := art.inputs.get(role), dict) and rec.get("sha256") == given.sha256
            for role, given in zip(("poses_a", "poses_b"), poses, strict=True)
        )
        if same and not metric:
            return joint, []
        made_with = art.inputs.get("joint")
        hint = (
            f" (this one was estimated with {made_with['path']})"
            if isinstance(made_with, dict) and made_with.get("path")
            else ""
        )
        raise InputError(
            "is an unknown-scale relpose.yaml: its joint is in the units of the two "
            "trajectories it was estimated from (position_in_a in A's, position_in_b in B's), "
            + ("not metres" if metric else "and these are other trajectories")
            + ". Give a metric joint.yaml from a fixed-joint session (acscal joint) with "
            f"--joint-metric{hint}, or --self-calibrate; its joint can be reused as --joint "
            "only with the same two trajectories",
            path=path,
        )
    if unknown_scale and not metric:
        return joint, []
    have = art.length_unit
    need = "m" if metric else length_unit
    if have == need:
        return joint, []
    if have in METRES_PER_UNIT and need in METRES_PER_UNIT:
        factor = METRES_PER_UNIT[have] / METRES_PER_UNIT[need]
        return joint.scaled(factor, need), [
            f"the joint ({path}) is in {have} and the trajectories in {need}: its positions "
            f"and covariances were converted to {need} (x {factor:g})"
        ]
    raise InputError(
        f"the joint is in '{have}' but the trajectories are in '{need}'"
        + (" (--joint-metric needs metres)" if metric else " (--length-unit)")
        + f": give a joint in {need}, or the --length-unit of the trajectories; only "
        f"{', '.join(METRES_PER_UNIT)} are converted",
        path=path,
    )
