"""The relative-pose stage: ``acscal relpose`` (Algorithms III, IV and self-calibration)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.core.diagnose import diagnose_relpose, fit_is_suspicious
from acs_cli.core.joint import near_hinge_warning
from acs_cli.core.pairing import PairingResult
from acs_cli.core.quality import (
    Measure,
    joint_measures,
    judge,
    length_scale,
    relative_pose_measures,
)
from acs_cli.core.relpose import (
    JointPrior,
    RelposeEstimate,
    check_joint_type,
    estimate_relpose,
    in_pair_words,
    paper_pose_std,
)
from acs_cli.core.rig_solve import TEST_SETTLED_NOISE
from acs_cli.core.se3 import FloatArray
from acs_cli.core.time_offset import (
    PoseInterpolator,
    TimeOffset,
    estimate_time_offset,
    synchronisation_check,
)
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header, to_plain
from acs_cli.io.atomic import check_distinct_output, check_writable
from acs_cli.io.joint import FramesUsed, JointSection, MotionQuality, PoseNoise, UncertaintySection
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.relpose import (
    RelativePose,
    RelposeArtifact,
    RelposeQuality,
    Scale,
    TimeOffsetSection,
)
from acs_cli.io.trajectory import Trajectory
from acs_cli.io.verdict import VerdictSection
from acs_cli.stages.bundle import bundle_general
from acs_cli.stages.common import (
    PairedTrajectories,
    StageRun,
    input_files,
    load_poses,
    pair_loaded,
    pairing_section,
)
from acs_cli.stages.joint import (
    QUATERNION_FORMATS,
    paper_misfit,
    read_joint_in_units,
    timed_pair,
)

#: Default largest time offset searched, seconds.
DEFAULT_MAX_OFFSET = 0.5


@dataclass(frozen=True)
class RelposeConfig:
    """Options of the relative-pose stage.

    Attributes
    ----------
    method : {"refined", "paper"}
    unknown_scale : bool
        Each trajectory's translations carry an unknown factor (Algorithm IV).
    self_calibrate : bool
        Estimate the joint from this recording alone (no joint file).
    joint_metric : bool
        The joint file is metric while the trajectories have unknown scales.
    reference : int
        Index (among the paired frames) of the reference instant.
    format_a, format_b, pair_by, max_dt, length_unit
        As for the joint stage.
    bundle : bool
        Refined method, known scale: when both poses NPZs carry their corners (``acscal
        poses``), refine the relative pose, the joint and the intrinsics by a bundle
        adjustment on them, fused with the given joint.
    estimate_time_offset : bool
        Estimate a constant offset between the cameras' clocks with the calibration
        (:mod:`acs_cli.core.time_offset`); both trajectories need timestamps.
    max_offset : float
        Largest offset searched, seconds.
    accept_weak : bool
        Write a result past a refusal level of :mod:`acs_cli.core.quality` anyway, marked
        weak (``--accept-weak``).
    joint_type : {"ball", "hinge", "rigid"}
        The two-body rig's joint (``--joint-type``; refined method only unless ball). A
        hinge adds its axis in each camera to ``joint``; a rigid mount has no joint point:
        ``relpose.yaml`` then has no ``joint`` section, and a joint file is refused.
    """

    method: str = "refined"
    unknown_scale: bool = False
    self_calibrate: bool = False
    joint_metric: bool = False
    reference: int = 0
    format_a: str = "auto"
    format_b: str = "auto"
    pair_by: str = "auto"
    max_dt: float | None = None
    length_unit: str = "m"
    bundle: bool = True
    estimate_time_offset: bool = False
    max_offset: float = DEFAULT_MAX_OFFSET
    accept_weak: bool = False
    joint_type: str = "ball"


RelposeRun = StageRun[RelposeEstimate]


def load_prior(
    path: Path,
    metric: bool,
    *,
    length_unit: str = "m",
    unknown_scale: bool = False,
    poses: tuple[PosesArtifact, PosesArtifact] | None = None,
    warnings: list[str] | None = None,
) -> JointPrior:
    """A :class:`JointPrior` from a ``joint.yaml`` (or a ``relpose.yaml``'s joint), in the
    trajectories' unit (:func:`acs_cli.stages.joint.read_joint_in_units`; a conversion's
    note is appended to ``warnings``).

    A position without a covariance takes the squares of its standard deviations.
    """
    joint, notes = read_joint_in_units(
        path, length_unit, unknown_scale=unknown_scale, metric=metric, poses=poses
    )
    if warnings is not None:
        warnings += notes
    return JointPrior(
        position_in_a=joint.position_in_a,
        position_in_b=joint.position_in_b,
        covariance_a=joint.covariance("a"),
        covariance_b=joint.covariance("b"),
        metric=metric,
    )


def _units(config: RelposeConfig) -> dict[str, str]:
    if not config.unknown_scale:
        return {"length": config.length_unit, "angles": "deg"}
    return {
        "length": "B units (camera B's trajectory units) for T_b_a and position_in_b; "
        "A units for position_in_a",
        "angles": "deg",
        "scale": "phi_ba = mu_b / mu_a; mu = trajectory units per metre",
    }


def run_relpose(
    poses_a: Path | PosesArtifact,
    poses_b: Path | PosesArtifact,
    joint: Path | None,
    output: Path,
    config: RelposeConfig,
) -> RelposeRun:
    """Read the trajectories (each once, unless given read) and the joint, estimate the
    relative pose, write ``relpose.yaml``.

    Raises
    ------
    InputError
        Bad files or options.
    DegenerateMotionError
        The motion cannot determine the answer (nothing is written).
    """
    check_joint_type(config.joint_type, config.method)
    rigid = config.joint_type == "rigid"
    if rigid and joint is not None:
        raise InputError(
            "a rigid joint has no joint point to take from a joint file: drop --joint "
            "(--joint-metric), or declare the joint a ball or a hinge"
        )
    if config.self_calibrate and joint is not None:
        raise InputError("--self-calibrate estimates the joint; do not also give a joint file")
    if not config.self_calibrate and joint is None and not rigid:
        raise InputError(
            "give the joint (--joint joint.yaml or --joint-metric joint.yaml), or "
            "--self-calibrate to estimate it from this recording"
        )
    if config.joint_metric and not config.unknown_scale:
        raise InputError("--joint-metric only makes sense with --unknown-scale")
    pa, pb = load_poses(poses_a, config.format_a), load_poses(poses_b, config.format_b)
    inputs: dict[str, Path | PosesArtifact] = {"poses_a": pa, "poses_b": pb}
    if joint is not None:
        inputs["joint"] = joint
    check_distinct_output(output, input_files(inputs))
    check_writable(output)
    joint_notes: list[str] = []
    prior = (
        None
        if joint is None
        else load_prior(
            joint,
            config.joint_metric,
            length_unit=config.length_unit,
            unknown_scale=config.unknown_scale,
            poses=(pa, pb),
            warnings=joint_notes,
        )
    )
    traj_a, traj_b = pa.trajectory, pb.trajectory

    def fit(Ta: FloatArray, Tb: FloatArray) -> FloatArray:
        """The joint residuals of the refined estimate on one pairing (for the time offset)."""
        return estimate_relpose(
            Ta,
            Tb,
            prior,
            unknown_scale=config.unknown_scale,
            reject_outliers=False,
            noise_tolerance=TEST_SETTLED_NOISE,
            joint_type=config.joint_type,
        ).residuals

    offset = None
    if config.estimate_time_offset:
        pair, offset = _pair_with_offset(traj_a, traj_b, config, fit)
    else:
        pair = pair_loaded(traj_a, traj_b, config.pair_by, config.max_dt)
    warnings = joint_notes + list(pair.warnings)
    est = estimate_relpose(
        pair.a.T_world_cam,
        pair.b.T_world_cam,
        prior,
        unknown_scale=config.unknown_scale,
        reference=config.reference,
        method=config.method,
        accept_weak=config.accept_weak,
        joint_type=config.joint_type,
    )
    if offset is None and config.method == "refined":
        warnings += _synchronisation(traj_a, traj_b, fit)
    if offset is not None and offset.at_limit:
        warnings.append(
            f"the time offset {offset.offset_s:+.4f} s lies at the edge of the range searched "
            f"(+-{config.max_offset:g} s): the clocks may differ by more; search a larger "
            "--max-offset"
        )
    bundle_section = None
    if config.method == "refined" and config.bundle and offset is None:
        est, bundle_section, notes = bundle_general((pa, pb), pair, est, prior)
        warnings += notes
    rpy_std, t_std = paper_pose_std(est.T_b_a, est.covariance)
    rel = RelativePose(
        T_b_a=est.T_b_a,
        T_b_a_covariance=est.covariance,
        rpy_deg=est.rpy_deg,
        rpy_deg_std=rpy_std,
        translation_b_in_a=est.translation_b_in_a,
        translation_b_in_a_std=t_std,
        reference=int(est.reference),
        reference_timestamp_a=float(pair.a.timestamps[est.reference]),
        reference_timestamp_b=float(pair.b.timestamps[est.reference]),
        T_wb_wa=est.T_wb_wa,
    )
    # a rigid mount has no joint point: no joint section (the header's method says rigid)
    joint_sec = (
        JointSection.from_estimate(
            est.position_in_a,
            est.covariance_a,
            est.position_in_b,
            est.covariance_b,
            source="self-calibrated from this recording"
            if est.self_calibrated
            else "refined from the given joint and this recording"
            if est.method == "refined"
            else "the given joint, position_in_a refined by the paper's LM",
        ).with_axes(
            est.joint_type,
            _axes(est.axis_in_a, est.axis_in_b),
            _axes(est.axis_in_a_std_deg, est.axis_in_b_std_deg),
        )
        if est.has_point
        else None
    )
    scale = None
    if config.unknown_scale:
        scale = Scale(
            phi_ba=float(est.phi_ba),
            phi_ba_std=_float_or_none(est.phi_std),
            mu_a=_float_or_none(est.mu_a),
            mu_a_std=_float_or_none(est.mu_a_std),
            mu_b=_float_or_none(est.mu_b),
            mu_b_std=_float_or_none(est.mu_b_std),
        )
    frames = FramesUsed.from_inliers(est.inliers, pair.a.timestamps)
    if frames.rejected:
        warnings.append(f"{len(frames.rejected)} frame(s) rejected as outliers")
    if est.self_calibrated:  # a given joint supplies what a near-hinge motion cannot
        near = near_hinge_warning(
            "the joint",
            {c.upper(): m for c, m in est.motion.items()},
            {"A": est.covariance_a, "B": est.covariance_b},
            {"A": "A units", "B": "B units"} if config.unknown_scale else config.length_unit,
        )
        warnings += [] if near is None else [near]
    if est.rig is not None:  # a joint that fits its declared type poorly
        warnings += [in_pair_words(w) for w in est.rig.warnings]
    note = None if est.rig is None else est.rig.correlated.message("the relative pose")
    warnings += [] if note is None else [note]
    findings = relpose_findings(est, pair, prior, config, timed=offset is None)
    verdict = judge(relpose_verdict_measures(est, pair), config.accept_weak, findings)
    warnings += verdict.warnings()
    quality = RelposeQuality(
        residual_rms=float(est.residual_rms),
        frames=frames,
        pairing=pairing_section(pair.pairing, config.pair_by),
        estimated_pose_noise=PoseNoise(
            float(est.noise["sigma_trans"]), float(est.noise["sigma_rot_deg"])
        )
        if est.noise
        else None,
        bundle_adjustment=bundle_section or {},
        motion=MotionQuality.of(est.motion, {"a": est.covariance_a, "b": est.covariance_b}),
        uncertainty=None if est.rig is None else UncertaintySection.of(est.rig.correlated),
    )
    mode = (
        "a rigid mount (constant T_b_a: hand-eye calibration; no joint point)"
        if rigid
        else "self-calibration"
        if est.self_calibrated
        else ("Algorithm IV" if config.unknown_scale else "Algorithm III")
    )
    if config.joint_type == "hinge":
        mode += ", the joint declared a hinge (its point: the axis point nearest A's centre)"
    method_text = (
        f"paper: {mode} as published (linear eq. (24), SVD projection, LM over roll, pitch, "
        "yaw, T_BA, O_A" + (", phi" if config.unknown_scale else "") + ")"
        if config.method == "paper"
        else f"refined: {mode}; "
        + ("T_b_a" if rigid else "joint in both cameras")
        + ", world-to-world "
        + ("similarity" if config.unknown_scale else "rigid transform")
        + " by weighted ML over all frames, reference poses corrected by the joint constraint"
        + (
            "; then a bundle adjustment on both cameras' corners (intrinsics, joint, "
            "world-to-world transform, per-frame poses of A"
            + ("" if rigid else " and joint rotations")
            + ")"
            if bundle_section is not None
            else ""
        )
    )
    header = make_header(
        "relpose",
        inputs,
        method=method_text,
        units=_units(config),
        frames={
            "T_b_a": "maps points of camera A's frame into camera B's at the reference instant "
            "(the paper's H_BA)",
            "rpy_deg": "roll, pitch, yaw of R_a_b (R = Rz(yaw) Ry(pitch) Rx(roll))",
            "translation_b_in_a": "camera B's origin in camera A's frame (t_a_b)",
            "T_b_a_covariance": "of (rotation vector perturbation on the right, rad; t_b_a)",
            "T_wb_wa": "maps world A into world B (rotation and translation of the similarity)",
        },
    )
    art = RelposeArtifact(
        relative_pose=rel,
        joint=joint_sec,
        scale=scale,
        quality=quality,
        verdict=VerdictSection.from_verdict(verdict),
        warnings=warnings,
        time_offset=None
        if offset is None
        else TimeOffsetSection(
            time_offset_s=offset.offset_s,
            time_offset_s_std=offset.std_s if np.isfinite(offset.std_s) else None,
            max_offset_s=config.max_offset,
            frames=int(offset.frames.sum()),
        ),
        header=header,
        source=str(output),
        joint_type=None if config.joint_type == "ball" else config.joint_type,
    )
    art.save(output)
    return StageRun(est, to_plain(art.to_doc()), output, warnings)


def relpose_findings(
    est: RelposeEstimate,
    pair: PairedTrajectories,
    prior: JointPrior | None,
    config: RelposeConfig,
    timed: bool,
) -> list[str]:
    """What a usual cause explains (:func:`acs_cli.core.diagnose.diagnose_relpose`) when the
    residual is suspicious against the rig's length scale in B (the verdict's scale);
    ``timed``: also try the clocks (not when the offset was estimated)."""
    Ta, Tb = pair.a.T_world_cam, pair.b.T_world_cam
    if est.joint_type != "ball":  # the diagnosis refits ball joints
        return []
    if not fit_is_suspicious(est.residual_rms, length_scale(est.position_in_b, Tb)):
        return []
    unit = "B units" if config.unknown_scale else config.length_unit
    refined = partial(estimate_relpose, Ta, Tb, prior, unknown_scale=config.unknown_scale)
    found = paper_misfit(est.method, est.residual_rms, refined, "ab", unit)
    if found is not None:
        return [found.message]
    found = diagnose_relpose(
        Ta,
        Tb,
        prior,
        current_rms=est.residual_rms,
        unknown_scale=config.unknown_scale,
        quaternion_source=(
            pair.a.format in QUATERNION_FORMATS,
            pair.b.format in QUATERNION_FORMATS,
        ),
        timed=timed_pair(pair) if timed else None,
        max_offset=config.max_offset,
        unit=unit,
    )
    return [] if found is None else [found.message]


def relpose_verdict_measures(est: RelposeEstimate, pair: PairedTrajectories) -> list[Measure]:
    """The quality measures of a relative pose (:mod:`acs_cli.core.quality`): the joint in
    each camera (B's with the residual, which is in B's units, and the rejected share), and
    ``T_b_a`` (and ``phi_ba`` under unknown scale)."""
    Ta, Tb = pair.a.T_world_cam, pair.b.T_world_cam
    out: list[Measure] = []
    if est.has_point:
        kind = est.joint_type
        out += joint_measures(
            est.position_in_a, est.covariance_a, Ta, None, None, "the joint in A", kind
        )
        out += joint_measures(
            est.position_in_b, est.covariance_b, Tb, est.residual_rms, est.inliers,
            "the joint in B", kind,
        )  # fmt: skip
    out += relative_pose_measures(
        est.T_b_a,
        est.covariance,
        length_scale(est.position_in_b, Tb),
        est.phi_ba if est.unknown_scale else None,
        est.phi_std if est.unknown_scale else None,
    )
    return out


def _pair_with_offset(
    a: Trajectory,
    b: Trajectory,
    config: RelposeConfig,
    fit: Callable[[FloatArray, FloatArray], FloatArray],
) -> tuple[PairedTrajectories, TimeOffset]:
    """Estimate the clocks' offset and pair A's poses with B's interpolated at ``t + dt``."""
    if config.method != "refined":
        raise InputError("--estimate-time-offset needs the refined method (not --method paper)")
    for name, t in (("A", a), ("B", b)):
        if not t.has_timestamps or t.time_unit != "s":
            raise InputError(
                f"--estimate-time-offset needs timestamps in seconds, but camera {name}'s "
                "trajectory "
                + (
                    "has frame numbers (give `acscal poses` --fps or --timestamps)"
                    if t.has_timestamps
                    else f"has none ({t.format})"
                ),
                path=t.source,
            )
    offset = estimate_time_offset(
        a.timestamps, a.T_world_cam, b.timestamps, b.T_world_cam, fit, config.max_offset
    )
    idx = np.flatnonzero(offset.frames)
    interp = PoseInterpolator(b.timestamps, b.T_world_cam)
    tb = a.timestamps[idx] + offset.offset_s
    keep = interp.valid(tb)  # the search range's frames, valid at the estimate too
    idx, tb = idx[keep], tb[keep]
    b_at = Trajectory(tb, interp(tb), b.source, b.format, True)
    nearest = np.clip(np.searchsorted(b.timestamps, tb), 0, len(b) - 1)
    pairing = PairingResult(
        idx_a=idx,
        idx_b=nearest,
        unpaired_a=len(a) - idx.size,
        unpaired_b=0,
        max_dt=float(interp.max_gap),
    )
    notes = []
    if len(a) - idx.size:
        notes.append(
            f"{len(a) - idx.size} of {len(a)} poses of A fall outside camera B's recording "
            f"once shifted by up to +-{config.max_offset:g} s, and were left out"
        )
    notes.append(
        f"camera B's poses are interpolated at A's times + {offset.offset_s:+.4f} s (SE(3) "
        "splines); no bundle adjustment on the corners"
    )
    return PairedTrajectories(a.select(idx), b_at, pairing, notes), offset


def _synchronisation(
    a: Trajectory, b: Trajectory, fit: Callable[[FloatArray, FloatArray], FloatArray]
) -> list[str]:
    """A warning when shifting B's clock by up to a frame fits clearly better."""
    if not (a.has_timestamps and b.has_timestamps) or "frame" in (a.time_unit, b.time_unit):
        return []
    found = synchronisation_check(a.timestamps, a.T_world_cam, b.timestamps, b.T_world_cam, fit)
    if found is None:
        return []
    dt, ratio = found
    return [
        f"shifting camera B's timestamps by {1e3 * dt:+.1f} ms makes the joint residual "
        f"{100 * (1 - ratio):.0f}% smaller: the cameras are probably not synchronised; "
        "estimate the offset with --estimate-time-offset"
    ]


def _axes(a: Any, b: Any) -> dict[str, Any]:
    """``{"a": a, "b": b}`` without the Nones."""
    return {k: v for k, v in (("a", a), ("b", b)) if v is not None}


def _float_or_none(x: Any) -> float | None:
    return None if x is None else float(x)
