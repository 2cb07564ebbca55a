"""The rig stage: every camera and joint of a rig calibrated at once (``rig.yaml``).

A rig run config (``schema_version: 2``) names cameras and the joints between them::

    schema: acscal/run-config
    schema_version: 2
    output: out/
    reference: {camera: cam0, frame: 0}
    cameras:
      cam0: {poses: cam0.tum}                  # TUM, KITTI, COLMAP or NPZ
      cam1: {poses: cam1.tum, scale: unknown}  # monocular SLAM: metric scale unknown
      cam2: {images: imgs/cam2, model: pinhole}  # intrinsics and poses from a board
    joints:
      j01: {between: [cam0, cam1], type: ball}
      j12: {between: [cam1, cam2], type: hinge}

:func:`parse_rig_config` (:mod:`acs_cli.io.config`) checks it (every error names the key);
:func:`run_rig` reads each camera's trajectory, puts all cameras on one timeline, solves the
whole rig (:func:`acs_cli.core.rig_solve.estimate_rig`) and writes ``rig.yaml``
(:class:`acs_cli.io.rig.RigArtifact`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from acs_cli.core import se3
from acs_cli.core.angles import hinge_angle_range_deg
from acs_cli.core.joints import joint_model
from acs_cli.core.pairing import common_timeline
from acs_cli.core.quality import (
    REJECTED,
    RESIDUAL,
    Measure,
    judge,
    largest_std,
    length_scale,
    std_rule,
)
from acs_cli.core.rig import RigJoint, hinge_point_from_nearest, oriented_axis, rig_topology
from acs_cli.core.rig_bundle import (
    CameraViews,
    PoseBodyEstimate,
    RigidEdgeEstimate,
    bundle_adjust_rig,
)
from acs_cli.core.rig_solve import (
    TEST_SETTLED_NOISE,
    CameraTrack,
    EdgeEstimate,
    EdgePrior,
    Recordings,
    RigEstimate,
    edge_motion,
    estimate_rig,
    fixed_joint_prior,
    held_priors,
    merge_priors,
    near_hinge_warnings,
)
from acs_cli.core.se3 import FloatArray
from acs_cli.core.time_offset import (
    Fit,
    PoseInterpolator,
    estimate_time_offset,
    synchronisation_check,
)
from acs_cli.errors import DegenerateMotionError, InputError
from acs_cli.io.artifacts import make_header
from acs_cli.io.config import RigCameraSpec as RigCameraSpec  # the config, as before
from acs_cli.io.config import RigJointSpec as RigJointSpec
from acs_cli.io.config import RigRecordingSpec, RigRunConfig
from acs_cli.io.config import is_rig_config as is_rig_config
from acs_cli.io.config import parse_rig_config as parse_rig_config
from acs_cli.io.joint import BundleSection, MotionQuality, UncertaintySection
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.rig import (
    PoseOnlySection,
    RigArtifact,
    RigCameraResult,
    RigJointResult,
    RigRecordingResult,
    RigWorldResult,
)
from acs_cli.io.rig_residuals import RESIDUALS_FILE, JointResiduals, write_joint_residuals
from acs_cli.io.trajectory import Trajectory, write_tum
from acs_cli.io.verdict import VerdictSection
from acs_cli.stages.bundle import (
    CornerViews,
    bundle_frames,
    corner_views,
    held_note,
    rig_sections,
)
from acs_cli.stages.common import load_poses

RIG_FILE = "rig.yaml"


# --------------------------------------------------------------------------- stage


@dataclass(frozen=True)
class RigRun:
    """What :func:`run_rig` did."""

    estimate: RigEstimate
    artifact: RigArtifact
    output: Path
    warnings: list[str]


def tracks_on_timeline(
    config: RigRunConfig,
    trajectories: dict[str, Trajectory],
    recording: RigRecordingSpec | None = None,
) -> tuple[dict[str, CameraTrack], np.ndarray, dict[str, np.ndarray], list[str]]:
    """Every camera's poses on one timeline; checks that neighbours share instants.

    With ``recording``, the cameras and joints of that recording (those with both bodies in
    it and not held still there).

    Returns the tracks, the timeline (seconds or frame numbers), each camera's row of its
    trajectory at every instant (-1 where it has none) and warnings.

    Raises
    ------
    InputError
        Two cameras joined by a joint with no instant in common (naming the joint's key).
    """
    by_time = config.pair_by == "timestamp" or (
        config.pair_by == "auto" and all(t.has_timestamps for t in trajectories.values())
    )
    if by_time:
        for name, t in trajectories.items():
            if not t.has_timestamps:
                raise InputError(
                    f"cameras.{name}: the trajectory has no timestamps ({t.format}); set "
                    "pair_by: index",
                    path=t.source,
                )
        units = {t.time_unit for t in trajectories.values()}
        if len(units) > 1:
            frames = [n for n, t in trajectories.items() if t.time_unit == "frame"]
            raise InputError(
                f"cameras {', '.join(frames)} have frame numbers for times and the others "
                f"seconds: {'; '.join(time_advice(config, n) for n in frames)}",
                path=config.path,
            )
        slots, index = common_timeline(
            {n: t.timestamps for n, t in trajectories.items()}, config.max_dt
        )
    else:
        m = max(len(t) for t in trajectories.values())
        slots = np.arange(m, dtype=float)
        index = {
            n: np.where(np.arange(m) < len(t), np.arange(m), -1) for n, t in trajectories.items()
        }
    warnings: list[str] = []
    if not by_time:
        lengths = {n: len(t) for n, t in trajectories.items()}
        if len(set(lengths.values())) > 1:
            warnings.append(
                "poses paired by index, but the cameras have different numbers of poses ("
                + ", ".join(f"{n}: {k}" for n, k in lengths.items())
                + "): frame i of one camera is taken as frame i of the others; check the "
                "pairing if a joint fits poorly"
            )
    for j in config.topology.joints:
        p, q = j.between
        if p not in index or q not in index:
            continue
        if recording is not None and j.name in recording.fixed_joints:
            continue
        common = int(np.sum((index[p] >= 0) & (index[q] >= 0)))
        if common == 0:
            tp, tq = trajectories[p].timestamps, trajectories[q].timestamps
            raise InputError(
                f"joints.{j.name}: cameras {p} ({tp[0]:.6f}..{tp[-1]:.6f}) and {q} "
                f"({tq[0]:.6f}..{tq[-1]:.6f}) have no instant in common; are they on the same "
                "clock?",
                path=config.path,
            )
    tracks: dict[str, CameraTrack] = {}
    for name, t in trajectories.items():
        idx = index[name]
        valid = idx >= 0
        T = np.broadcast_to(np.eye(4), (slots.size, 4, 4)).copy()
        T[valid] = t.T_world_cam[idx[valid]]
        left = len(t) - int(valid.sum())
        if left:
            warnings.append(f"{member(config, name)}: {left} of {len(t)} poses share no instant")
        tracks[name] = CameraTrack(T, valid, config.cameras[name].unknown_scale)
    return tracks, slots, index, warnings


def check_prior_units(config: RigRunConfig) -> None:
    """Priors in metres (``position_in``, fixed-joint sessions) need a metric reference
    camera, and a fixed-joint session a metric camera.

    Raises
    ------
    InputError
        Naming the key of the first prior that cannot be used.
    """
    ref_unknown = config.cameras[config.reference_camera].unknown_scale
    for name, j in config.joints.items():
        if j.position_in and ref_unknown:
            raise InputError(
                f"joints.{name}.position_in is in metres, but the reference camera "
                f"{config.reference_camera} has an unknown scale: choose a metric camera as "
                "reference.camera",
                path=config.path,
            )
        for cam in j.fixed_joint:  # (recordings that hold a joint: the engine checks)
            if config.cameras[cam].unknown_scale or ref_unknown:
                raise InputError(
                    f"joints.{name}.fixed_joint.{cam}: a fixed-joint session gives metres; it "
                    f"needs {cam} and the reference camera to be metric (scale: known)",
                    path=config.path,
                )


def _priors(config: RigRunConfig) -> tuple[dict[str, EdgePrior], dict[str, PosesArtifact]]:
    """Joint priors: positions given in the config, and fixed-joint session files
    (``joints.<j>.fixed_joint``: Algorithm II, :func:`~acs_cli.core.rig_solve.fixed_joint_prior`),
    and the session files read, by their role in the header (``fixed_joint_<j>_<cam>``).
    Recordings that hold a joint still (``recordings.<r>.fixed_joints``) are the engine's
    (:class:`~acs_cli.core.rig_solve.Recordings`)."""
    check_prior_units(config)
    out = {}
    sessions: dict[str, PosesArtifact] = {}
    for name, j in config.joints.items():
        cov = None if j.position_std is None else np.eye(3) * j.position_std**2
        prior = EdgePrior(
            position_in=dict(j.position_in),
            covariance_in={c: cov for c in j.position_in} if cov is not None else {},
        )
        joint = config.topology.joint(name)
        for cam, path in j.fixed_joint.items():
            key = f"joints.{name}.fixed_joint.{cam}"
            try:
                sessions[f"fixed_joint_{name}_{cam}"] = got = PosesArtifact.load(path)
            except InputError as exc:
                raise InputError(f"{key}: {exc.message}", path=exc.path, line=exc.line) from None
            T = got.trajectory.T_world_cam
            prior = merge_priors(prior, fixed_joint_prior(joint, cam, T, f"{key} (camera {cam})"))
        if prior.position_in or prior.line_in or prior.axis_in:
            out[name] = prior
    return out, sessions


def hinge_wobble_deg(e: EdgeEstimate) -> float | None:
    """A hinge's RMS rotation off its axis over the frames used (deg): its rotation rows,
    the axis's direction in one body against the other's; None for another joint type."""
    rot = e.residual_blocks.get("rot") if e.joint.type == "hinge" else None
    if rot is None or rot.size == 0:
        return None
    return float(np.degrees(np.sqrt(np.mean(np.sum(rot**2, axis=1)))))


#: Angle (deg) between a hinge's axis and the direction its config's ``axis`` gives beyond
#: which that direction barely tells the sign (a warning).
AXIS_DIRECTION_WARN_DEG = 80.0


def oriented_axes(config: RigRunConfig, est: RigEstimate) -> tuple[RigEstimate, list[str]]:
    """The hinges' axes with the signs the config's ``joints.<name>.axis`` asks for (the
    default, largest component in the first body positive, elsewhere), and warnings where
    the direction given is nearly across the axis or cannot be evaluated."""
    edges = dict(est.edges)
    notes: list[str] = []
    for name, spec in config.joints.items():
        e = edges.get(name)
        if e is None or not e.axis_in:
            continue
        if spec.axis_direction is not None:
            body, d = spec.axis_direction
            what = f"[{d[0]:+g}, {d[1]:+g}, {d[2]:+g}] in {body}'s frame"
        elif spec.axis_towards is not None:
            body = e.joint.between[0]
            T_p, T_t = est.cameras[body].T_cam_ref, est.cameras[spec.axis_towards].T_cam_ref
            if T_p is None or T_t is None:
                notes.append(
                    f"joint {name}: its axis keeps the default sign: {body} or "
                    f"{spec.axis_towards} has no pose at the reference instant, so 'towards "
                    f"{spec.axis_towards}' cannot be evaluated"
                )
                continue
            # the named body's origin in p's frame, from the joint's point
            d = (T_p @ se3.invert_transforms(T_t))[:3, 3] - e.position_in[body]
            what = f"towards {spec.axis_towards}"
        else:
            continue
        axis, angle = oriented_axis(e.axis_in, body, d)
        if angle > AXIS_DIRECTION_WARN_DEG:
            notes.append(
                f"joint {name}: its axis is {angle:.0f} deg from the direction its 'axis' "
                f"gives ({what}): that direction barely tells which way the axis points"
            )
        edges[name] = dataclasses.replace(e, axis_in=axis)
    return dataclasses.replace(est, edges=edges), notes


def chosen_points(config: RigRunConfig, est: RigEstimate) -> RigEstimate:
    """The hinges' points where the config's ``joints.<name>.point`` puts them: the axis
    point nearest the point given (in one of the joint's bodies), in both bodies' frames,
    with the covariance propagated from the joint's whole geometry (point and axis,
    :func:`~acs_cli.core.rig.hinge_point_from_nearest`); the default (the axis point
    nearest the first body's origin) elsewhere.

    A moved point's copies of the default one in each camera's own units and under
    independent noise alone (``position_own_in``, ``position_cov_model_in``: the two-camera
    commands' and the degeneracy tests', not the rig's outputs) are dropped, not left stale.
    """
    edges = dict(est.edges)
    for name, spec in config.joints.items():
        e = edges.get(name)
        if e is None or spec.point_nearest is None:
            continue
        body, given = spec.point_nearest
        p, q = e.joint.between
        x, C = hinge_point_from_nearest(
            e.geometry, e.geometry_covariance, e.joint.between.index(body), given
        )
        edges[name] = dataclasses.replace(
            e,
            position_in={p: x[0], q: x[1]},
            position_cov_in={p: C[:3, :3], q: C[3:, 3:]},
            position_own_in={},
            position_cov_model_in={},
        )
    return dataclasses.replace(est, edges=edges)


def point_notes(config: RigRunConfig) -> str:
    """What rig.yaml's ``position_in`` is, for its header's ``frames``: the joint in each
    camera's frame, and for each hinge whose point the config chooses, which."""
    chosen = [
        f"hinge {name}: the axis point nearest [{g[0]:g}, {g[1]:g}, {g[2]:g}] in {body}'s frame"
        for name, j in config.joints.items()
        if j.point_nearest is not None
        for body, g in [j.point_nearest]
    ]
    text = "the joint in each camera's frame"
    return text if not chosen else f"{text} ({'; '.join(chosen)})"


def hinge_angle_range(est: RigEstimate, name: str) -> tuple[float, float] | None:
    """A hinge's angle range over its frames used (deg, :func:`hinge_angle_range_deg`):
    zero at the rig's relative pose at the reference instant (``T_cam_ref``, the URDF's
    zero), about the axis in its first camera; None for another joint type, or where a
    camera has no pose at the reference instant."""
    e = est.edges[name]
    p, q = e.joint.between
    cp, cq = est.cameras[p], est.cameras[q]
    if e.joint.type != "hinge" or cp.T_cam_ref is None or cq.T_cam_ref is None:
        return None
    frames = np.asarray(e.inliers, dtype=int)
    if frames.size == 0 or p not in e.axis_in:
        return None
    R_p_q0 = cp.T_cam_ref[:3, :3] @ cq.T_cam_ref[:3, :3].T
    return hinge_angle_range_deg(
        cp.poses_in_reference_world[frames, :3, :3],
        cq.poses_in_reference_world[frames, :3, :3],
        R_p_q0,
        e.axis_in[p],
    )


def rig_artifact(
    est: RigEstimate, length_unit: str, warnings: list[str], recordings: str | None = None
) -> RigArtifact:
    """The ``rig.yaml`` content of an estimate (with a ``recordings`` section when
    ``recordings`` names the reference recording of a rig of several, or of one with a
    shared world)."""
    ref = est.topology.reference
    T_ref_refworld = se3.invert_transforms(
        est.cameras[ref].poses_in_reference_world[est.reference_frame]
    )
    cams = {
        c: RigCameraResult(
            name=c,
            T_cam_ref=e.T_cam_ref,
            rotation_std_deg=e.rotation_std_deg,
            translation_std=e.translation_std,
            unknown_scale=e.scale_std is not None,
            scale=e.scale,
            scale_std=e.scale_std,
            T_ref_world=None
            if e.T_cam_ref is None
            else T_ref_refworld @ e.world_to_reference_world,
            pose_only=_pose_only(e) if isinstance(e, PoseBodyEstimate) else None,
            sigma_rotation_deg=float(e.sigma_rot_deg) if np.isfinite(e.sigma_rot_deg) else None,
        )
        for c, e in est.cameras.items()
    }
    recs: dict[str, RigRecordingResult] = {}
    if est.recordings is not None and (recordings is not None or any(est.recordings.shared_world)):
        for i, rname in enumerate(est.recordings.names):
            worlds = {}
            for w in est.worlds:
                if w.recording != rname:
                    continue
                sd = np.sqrt(np.maximum(np.diag(w.covariance), 0.0))
                worlds[w.label] = RigWorldResult(
                    label=w.label,
                    bodies=w.cameras,
                    T_ref_world=T_ref_refworld @ w.T_ref_world if w.tied else w.T_ref_world,
                    rotation_std_deg=np.degrees(sd[:3]),
                    translation_std=sd[3:],
                    scale=w.scale,
                    scale_std=w.scale_std,
                    tied=w.tied,
                )
            recs[rname] = RigRecordingResult(
                rname,
                est.recordings.shared_world[i],
                int(np.sum(est.recordings.of_frame == i)),
                worlds,
            )
    joints = {}
    for name, e in est.edges.items():
        T_q_p_std = None
        if isinstance(e, RigidEdgeEstimate):
            T_q_p_std = _stds(e.T_q_p_covariance)
        joints[name] = RigJointResult(
            name=name,
            type=e.joint.type,
            between=e.joint.between,
            position_in=dict(e.position_in),
            position_std_in={
                c: np.sqrt(np.maximum(np.diag(C), 0.0)) for c, C in e.position_cov_in.items()
            },
            axis_in=dict(e.axis_in),
            axis_std_deg_in=dict(e.axis_std_deg_in),
            residual_rms=e.residual_rms,
            frames_used=e.frames_used,
            frames_rejected=e.frames_rejected,
            T_q_p=e.T_q_p if joint_model(e.joint.type).constant_transform else None,
            T_q_p_std=T_q_p_std,
            motion=MotionQuality.of(edge_motion(est, name), dict(e.position_cov_in)),
            wobble_rms_deg=hinge_wobble_deg(e),
            angle_range_deg=hinge_angle_range(est, name),
        )
    return RigArtifact(
        reference_camera=est.topology.reference,
        reference_frame=est.reference_frame,
        length_unit=length_unit,
        cameras=cams,
        joints=joints,
        warnings=list(warnings),
        recordings=recs,
        uncertainty=UncertaintySection.of(est.correlated),
        # a header of its own, so that an artifact built from arrays saves and loads back;
        # run_rig replaces it with the run's inputs
        header=make_header(
            "rig",
            {},
            "acs_cli.core.rig_solve.estimate_rig (from arrays)",
            {"length": length_unit, "angles": "deg"},
            {"T_cam_ref": f"maps {ref}'s frame at instant {est.reference_frame} into the camera's"},
        ),
    )


def _stds(C: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rotation (deg) and translation stds of a pose covariance ``(6, 6)``."""
    d = np.sqrt(np.maximum(np.diag(C), 0.0))
    return np.degrees(d[:3]), d[3:]


def _pose_only(e: PoseBodyEstimate) -> PoseOnlySection | None:
    """The ``pose_only`` section of a body the bundle fitted on its poses."""
    f = e.pose_fit
    if f is None:
        return None
    return PoseOnlySection(
        frames=f.frames,
        sigma_rotation_deg=f.sigma_rot_deg,
        sigma_translation=f.sigma_trans,
        rms_rotation_deg=f.rms_rot_deg,
        rms_translation=f.rms_trans,
        T_world_board=dict(f.T_world_board),
        T_world_board_std={c: _stds(C) for c, C in f.T_world_board_covariance.items()},
    )


def rig_verdict_measures(est: RigEstimate, reference: CameraTrack) -> list[Measure]:
    """The quality measures of a rig (:mod:`acs_cli.core.quality`): per ball or hinge
    joint, its position in each camera and its residual against the rig's length scale
    (the joint's distance, or a tenth of the reference camera's travel, as
    :func:`~acs_cli.core.rig_solve.estimate_rig` judges it); per joint, its rejected
    share."""
    here = reference.valid.copy()
    if est.recordings is not None:  # the reference recording's world: one origin, one unit
        recs = est.recordings
        here &= recs.of_frame == recs.of_frame[est.reference_frame]
    T_ref = reference.T_w_c[here]
    out: list[Measure] = []
    for name, e in est.edges.items():
        total = e.frames_used + e.frames_rejected
        if total:
            out.append(Measure(REJECTED, e.frames_rejected / total, f"joint {name}"))
        if not joint_model(e.joint.type).has_point:
            continue
        for c, o in e.position_in.items():
            std = largest_std(e.position_cov_in[c])
            rule = std_rule(e.joint.type)
            out.append(Measure(rule, std / length_scale(o, T_ref), f"joint {name} in {c}"))
        # the joint's residual (reference units) against its distance from its first camera
        o_p = e.position_in[e.joint.between[0]]
        scale = length_scale(o_p, T_ref)
        out.append(Measure(RESIDUAL, e.residual_rms / scale, f"joint {name}"))
    return out


def run_rig(
    config: RigRunConfig,
    poses: Mapping[str, Path | PosesArtifact] | None = None,
    output: Path | None = None,
) -> RigRun:
    """Read every camera's trajectory (each file once), solve the rig, write ``rig.yaml``
    atomically.

    Parameters
    ----------
    config : RigRunConfig
    poses : dict of str to Path or PosesArtifact, optional
        By camera label (:func:`label`): the trajectory files of cameras configured with
        ``images`` (written by the poses stage), and any camera's poses already read.
    output : Path, optional
        Where to write (default ``config.output / "rig.yaml"``).
    """
    priors, sessions = _priors(config)
    files, by_rec = read_recordings(config, poses or {})
    turned, turns = shared_board_orders(config, files, by_rec)
    offsets: dict[str, tuple[float, float]] = {}
    single = config.single
    if single:
        trajectories = by_rec[config.reference_recording]
        if config.estimate_time_offset and config.recording_of_reference().fixed_joints:
            raise InputError(
                "estimate_time_offset: takes a recording that moves its joints (this one "
                "holds some still); give it without estimate_time_offset",
                path=config.path,
            )
        if config.estimate_time_offset:
            offsets, warnings = rig_time_offsets(config, trajectories, priors)
            tracks, slots, index = tracks_with_offsets(config, trajectories, offsets)
        else:
            tracks, slots, index, warnings = tracks_on_timeline(config, trajectories)
            warnings += rig_synchronisation(config, trajectories, priors)
        recordings = recordings_of(config, [slots.size])
        clocks = {config.reference_recording: offsets} if offsets else {}
    else:
        tracks, slots, recordings, index, warnings, clocks = tracks_of_recordings(
            config, by_rec, priors
        )
    warnings += turned
    k = recording_frame(config, recordings)
    try:
        est = estimate_rig(
            config.topology,
            tracks,
            reference_frame=k,
            priors=priors,
            accept_weak=config.accept_weak,
            recordings=recordings,
        )
    except DegenerateMotionError as exc:
        found = pose_format_diagnosis(config, tracks, k, priors, recordings)
        if not found:
            raise
        # a file in another convention is bad input (exit 2), named with the key
        raise InputError(
            f"{found}; as given, {exc.message[0].lower()}{exc.message[1:]}", path=config.path
        ) from None
    for name, e in est.edges.items():
        if e.frames_rejected:
            warnings.append(
                f"joint {name}: {e.frames_rejected} of {e.frames_used + e.frames_rejected} "
                "frames rejected as outliers"
            )
    sections: dict[str, BundleSection] = {}
    has_corners = any(p.corners is not None for p in files.values())
    if config.bundle and not clocks and has_corners:
        trajectories = {label(config, r, c): t for r, got in by_rec.items() for c, t in got.items()}
        # a recording's joints held still enter as their Algorithm II priors (as in the
        # pose-based solve), and its frames stay out of the bundle
        held = held_priors(config.topology, tracks, recordings)
        both = {j: merge_priors(priors[j], held[j]) if j in held else priors[j] for j in priors}
        both |= {j: p for j, p in held.items() if j not in priors}
        est, sections, notes = rig_bundle(config, files, trajectories, index, est, turns, both)
        warnings += notes
    est, axis_notes = oriented_axes(config, est)
    warnings += axis_notes
    ref_unknown = config.cameras[config.reference_camera].unknown_scale
    unit = f"{config.reference_camera} units" if ref_unknown else "m"
    warnings += est.warnings  # joints that fit their declared type poorly
    warnings += near_hinge_warnings(est, unit, priors)
    note = est.correlated.message("the rig")
    warnings += [] if note is None else [note]
    verdict = judge(rig_verdict_measures(est, tracks[config.reference_camera]), config.accept_weak)
    warnings += verdict.warnings()
    # the hinges' points the config chooses: reported, not judged (the verdict above is the
    # calibration's, at the default point, whatever point the config asks for)
    est = chosen_points(config, est)
    art = dataclasses.replace(
        rig_artifact(est, unit, warnings, None if single else config.reference_recording),
        # the reference instant as the config gives it: a frame of the reference recording
        reference_frame=config.reference_frame,
        reference_recording=None if single else config.reference_recording,
        bundle_adjustment=sections,
        verdict=VerdictSection.from_verdict(verdict),
    )
    if offsets:
        cams = {
            c: dataclasses.replace(r, time_offset_s=offsets[c][0], time_offset_s_std=offsets[c][1])
            for c, r in art.cameras.items()
        }
        art = dataclasses.replace(art, cameras=cams)
    elif clocks:  # several recordings: each its own clocks
        recs = {
            name: dataclasses.replace(
                r, clock=clock_of(config, clocks[name]), time_offsets=clocks[name]
            )
            if name in clocks
            else r
            for name, r in art.recordings.items()
        }
        art = dataclasses.replace(art, recordings=recs)
    seen = config.recording_of_reference().cameras
    cams = {
        c: dataclasses.replace(r, invert=c in seen and seen[c].invert)
        for c, r in art.cameras.items()
    }
    art = dataclasses.replace(art, cameras=cams)
    out = output if output is not None else config.output / RIG_FILE
    header = make_header(
        "rig",
        {f"poses_{n.replace('/', '_')}": p for n, p in files.items()}
        | sessions
        | {"config": config.path},
        "one maximum-likelihood solve over every joint (acs_cli.core.rig_solve.estimate_rig): "
        "ball, hinge and rigid constraints on each camera's trajectory, per-camera "
        "world-to-reference similarities, noise levels per joint, outliers rejected"
        + (
            "; then a bundle adjustment of the whole rig on every camera's board corners "
            "(acs_cli.core.rig_bundle.bundle_adjust_rig): intrinsics, joints, boards and "
            "each frame's articulation"
            if sections
            else ""
        ),
        {
            "length": unit,
            "angles": "deg",
            "scale": f"{unit} per camera trajectory unit",
        },
        {
            "T_cam_ref": f"maps {config.reference_camera}'s frame at reference frame "
            f"{config.reference_frame} of recording {config.reference_recording} "
            f"(t = {slots[est.reference_frame]:.9f}) into the camera's",
            "position_in": point_notes(config),
            "axis_in": "hinge axis (unit) in each camera's frame",
        },
    )
    art = dataclasses.replace(art, header=header)
    art.save(out)
    write_rig_trajectories(est, tracks, slots, out.parent / TRAJECTORY_DIR)
    write_joint_residuals(out.parent / RESIDUALS_FILE, joint_residuals(est, slots))
    return RigRun(est, art, out, warnings)


def label(config: RigRunConfig, recording: str, camera: str) -> str:
    """A camera of a recording, in messages and stage names: ``cam`` in a config of one
    recording, ``recording/cam`` in one of several."""
    return camera if config.single else f"{recording}/{camera}"


def camera_key(config: RigRunConfig, recording: str, camera: str) -> str:
    """The config key of a camera entry."""
    return f"cameras.{camera}" if config.single else f"recordings.{recording}.cameras.{camera}"


def read_recordings(
    config: RigRunConfig, poses: Mapping[str, Path | PosesArtifact]
) -> tuple[dict[str, PosesArtifact], dict[str, dict[str, Trajectory]]]:
    """Every camera's poses in every recording, each read once.

    ``poses`` holds, by :func:`label`, the poses stage's files of cameras given as
    ``images``, and any camera's poses already read (``acscal run`` hashed them). Returns
    the poses by label and the trajectories (``invert`` applied) by recording and camera.
    """
    files: dict[str, PosesArtifact] = {}
    by_rec: dict[str, dict[str, Trajectory]] = {}
    for rname, rec in config.recordings.items():
        by_rec[rname] = {}
        for name, spec in rec.cameras.items():
            lab = label(config, rname, name)
            key = camera_key(config, rname, name)
            given = poses.get(lab, spec.poses)
            if given is None:
                raise InputError(f"{key}: no poses (run its poses stage first)")
            try:
                files[lab] = load_poses(given, spec.format if spec.poses is not None else "npz")
            except InputError as exc:  # name the config key with the file
                where = f"{key}.poses" if spec.poses is not None else f"poses of {lab}"
                raise InputError(f"{where}: {exc.message}", path=exc.path, line=exc.line) from None
            t = files[lab].trajectory
            if spec.invert:  # the file holds T_cam_world
                t = dataclasses.replace(t, T_world_cam=se3.invert_transforms(t.T_world_cam))
            by_rec[rname][name] = t
    return files, by_rec


def shared_board_orders(
    config: RigRunConfig,
    files: dict[str, PosesArtifact],
    by_rec: dict[str, dict[str, Trajectory]],
) -> tuple[list[str], dict[str, FloatArray]]:
    """Bring every camera of a shared world to one labelling of a symmetric checkerboard.

    Two cameras that see one checkerboard can label it in its two orders (see
    :func:`acs_cli.stages.bundle.shared_board_flip`); their worlds then differ by a half
    turn. For each joint between two cameras of a shared recording whose poses carry that
    board, the second camera's trajectory is turned to the first's order when its joint
    then fits with less than half the residual (:func:`acs_cli.stages.bundle.
    board_order_residuals`, as ``acscal joint --overlap`` does); the
    trajectories in ``by_rec`` are replaced. Returns what was turned, as warnings, and the
    half turn of each camera turned (by :func:`label`).
    """
    from acs_cli.stages.bundle import board_order_residuals, shared_board_flip

    notes: list[str] = []
    turns: dict[str, FloatArray] = {}
    for rname, rec in config.recordings.items():
        if not rec.shared_world:
            continue
        trajs = by_rec[rname]
        settled: set[str] = set()
        for step in config.topology.tree_order():
            j = step.joint
            a, b = step.source, step.target
            if a not in trajs or b not in trajs or b in settled or j.name in rec.fixed_joints:
                continue
            F = shared_board_flip((files[label(config, rname, a)], files[label(config, rname, b)]))
            settled.add(b)
            if F is None:
                continue
            tracks, _, _, _ = tracks_on_timeline(config, {a: trajs[a], b: trajs[b]}, rec)
            rms = board_order_residuals(j, a, tracks, F)
            if rms[1] < 0.5 * rms[0]:
                t = trajs[b]
                trajs[b] = dataclasses.replace(t, T_world_cam=F @ t.T_world_cam)
                turns[label(config, rname, b)] = F
                notes.append(
                    f"recording {rname}: camera {b} labelled the shared board in the other "
                    f"order than {a}; turned to {a}'s (joint {j.name}'s residual "
                    + (f"{rms[0]:.3g}" if np.isfinite(rms[0]) else "did not fit")
                    + f" -> {rms[1]:.3g})"
                )
    return notes, turns


#: Readings of a body's poses that a file in the wrong convention gives, tried when the rig
#: does not fit: (cause, what it means, the fix).
POSE_READINGS = (
    (
        "inverted",
        "T_{body}_world given where T_world_{body} is expected",
        "invert them (invert: true)",
    ),
    ("wxyz", "quaternions written w x y z, read as TUM's x y z w", "write them x y z w"),
    ("xyzw", "quaternions written x y z w, read as w x y z", "write them w x y z"),
)


def _reread(T: FloatArray, cause: str) -> FloatArray:
    from acs_cli.core.diagnose import reordered_quaternions

    if cause == "inverted":
        return np.asarray(se3.invert_transforms(T))
    return reordered_quaternions(T, -1 if cause == "wxyz" else 1)


def pose_format_diagnosis(
    config: RigRunConfig,
    tracks: dict[str, CameraTrack],
    k: int,
    priors: dict[str, EdgePrior],
    recordings: Recordings,
) -> str:
    """When the rig does not fit: the one body whose poses, read another way (inverted, or
    their quaternions in the other order), make every joint fit; in words, or ``""``.

    Only bodies given as ``poses`` files are tried (a robot controller's, a tracker's: a
    board's poses come from acscal). Each reading is a whole solve without outlier
    rejection; every reading that succeeds is named.
    """
    found: list[tuple[float, str]] = []
    for c, spec in config.cameras.items():
        if spec.poses is None:
            continue
        for cause, means, fix in POSE_READINGS:
            tr = tracks[c]
            T = tr.T_w_c.copy()
            T[tr.valid] = _reread(T[tr.valid], cause)
            trial = dict(tracks)
            trial[c] = CameraTrack(T, tr.valid, tr.unknown_scale)
            try:
                est = estimate_rig(
                    config.topology, trial, reference_frame=k, priors=priors,
                    reject_outliers=False, accept_weak=True, recordings=recordings,
                    noise_tolerance=TEST_SETTLED_NOISE,
                )  # fmt: skip
            except (DegenerateMotionError, InputError):
                continue
            how = "inverted" if cause == "inverted" else "with their quaternions reordered"
            worst = max(e.residual_rms for e in est.edges.values())
            what = means.format(body=c)
            key = camera_key(config, config.reference_recording, c) + ".poses"
            found.append((worst, f"{key}: body {c}'s poses fit the rig {how} ({what}): {fix}"))
    if not found:
        return ""
    # the readings whose worst joint residual is near the best's (a reading that only fits
    # the rotations leaves the translations off by the rig's size)
    best = min(w for w, _ in found)
    fits = [text for w, text in sorted(found) if w <= 2.0 * best]
    if len(fits) > 1:  # e.g. either body of a hand-eye pair: AX = ZB holds inverted too
        return "one of these readings fits the rig, which the poses cannot tell apart: " + (
            "; or ".join(fits)
        )
    return fits[0]


def recording_frame(config: RigRunConfig, recordings: Recordings) -> int:
    """The reference instant on the rig's timeline: ``reference.frame`` of the reference
    recording.

    Raises
    ------
    InputError
        The frame is outside the recording.
    """
    r = recordings.names.index(config.reference_recording)
    at = np.flatnonzero(recordings.of_frame == r)
    if config.reference_frame >= at.size:
        raise InputError(
            f"reference.frame: {config.reference_frame} is outside the {at.size} instants of "
            f"recording {config.reference_recording}",
            path=config.path,
        )
    return int(at[config.reference_frame])


def tracks_of_recordings(
    config: RigRunConfig,
    by_rec: dict[str, dict[str, Trajectory]],
    priors: dict[str, EdgePrior],
) -> tuple[
    dict[str, CameraTrack],
    np.ndarray,
    Recordings,
    dict[str, np.ndarray],
    list[str],
    dict[str, dict[str, tuple[float, float]]],
]:
    """Every recording's cameras on its own timeline (as :func:`tracks_on_timeline`; with
    ``estimate_time_offset``, each recording's clocks estimated on its own and its cameras
    interpolated, :func:`rig_time_offsets`), the timelines one after the other: the rig's
    tracks, times, recordings, each camera's row of its trajectory at every instant by
    :func:`label` (-1 outside its recording), warnings, and each recording's clock offsets
    (empty without ``estimate_time_offset``)."""
    parts: list[tuple[dict[str, CameraTrack], np.ndarray]] = []
    rows: list[tuple[str, dict[str, np.ndarray]]] = []
    warnings: list[str] = []
    clocks: dict[str, dict[str, tuple[float, float]]] = {}
    for rname, rec in config.recordings.items():
        trajs = by_rec[rname]
        if config.estimate_time_offset and len(trajs) > 1:
            clocks[rname], notes = rig_time_offsets(config, trajs, priors, rec)
            tr, slots, idx = tracks_with_offsets(config, trajs, clocks[rname])
        else:
            tr, slots, idx, notes = tracks_on_timeline(config, trajs, rec)
            notes += rig_synchronisation(config, trajs, priors, rec)
        rows.append((rname, idx))
        warnings += [f"recording {rname}: {w}" for w in notes]
        parts.append((tr, slots))
    n = sum(slots.size for _, slots in parts)
    tracks: dict[str, CameraTrack] = {}
    for c, spec in config.cameras.items():
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        valid = np.zeros(n, bool)
        at = 0
        for tr, slots in parts:
            if c in tr:
                T[at : at + slots.size] = tr[c].T_w_c
                valid[at : at + slots.size] = tr[c].valid
            at += slots.size
        tracks[c] = CameraTrack(T, valid, spec.unknown_scale)
    recordings = recordings_of(config, [slots.size for _, slots in parts])
    index: dict[str, np.ndarray] = {}
    at = 0
    for (rname, idx), (_, slots) in zip(rows, parts, strict=True):
        for c, r in idx.items():
            index[label(config, rname, c)] = np.full(n, -1)
            index[label(config, rname, c)][at : at + slots.size] = r
        at += slots.size
    times = np.concatenate([slots for _, slots in parts])
    return tracks, times, recordings, index, warnings, clocks


def recordings_of(config: RigRunConfig, sizes: list[int]) -> Recordings:
    """The engine's :class:`Recordings` of a config whose recordings have ``sizes``
    instants, one after the other on the rig's timeline."""
    recs = list(config.recordings.values())
    return Recordings(
        tuple(r.name for r in recs),
        np.concatenate([np.full(m, i, dtype=int) for i, m in enumerate(sizes)]),
        tuple(r.shared_world for r in recs),
        tuple(r.fixed_joints for r in recs),
    )


def _edge_fit(
    config: RigRunConfig, j: RigJoint, priors: dict[str, EdgePrior], shared: bool = False
) -> Fit:
    """One joint's calibration on its two cameras' paired poses: its raw residuals
    (``shared``: both cameras' poses in one world)."""
    p, q = j.between
    topo = rig_topology([p, q], [(j.name, [p, q], j.type)], p)
    prior = {j.name: priors[j.name]} if j.name in priors else {}

    def fit(Tp: FloatArray, Tq: FloatArray) -> dict[str, FloatArray]:
        ok = np.ones(Tp.shape[0], bool)
        tracks = {
            p: CameraTrack(Tp, ok, config.cameras[p].unknown_scale),
            q: CameraTrack(Tq, ok, config.cameras[q].unknown_scale),
        }
        recs = Recordings.single(Tp.shape[0], shared)
        est = estimate_rig(
            topo, tracks, priors=prior, reject_outliers=False, recordings=recs,
            noise_tolerance=TEST_SETTLED_NOISE,
        )  # fmt: skip
        return est.edges[j.name].residual_blocks

    return fit


def member(config: RigRunConfig, name: str) -> str:
    """How messages name rig member ``name``: "camera X" for an image folder, "body X" for a
    poses-only entry (a mocap segment, a robot flange, an INS)."""
    spec = config.cameras.get(name)
    return f"body {name}" if spec is not None and spec.images is None else f"camera {name}"


def time_advice(config: RigRunConfig, name: str) -> str:
    """How camera ``name`` gets times in seconds, in the keys its kind of entry takes: an
    image folder takes ``fps`` or ``timestamps``; a ``poses:`` file carries its own times."""
    spec = config.cameras.get(name)
    if spec is not None and spec.images is None:
        return (
            f"cameras.{name}.poses: give its poses with times in seconds (a TUM file's first "
            "column; an NPZ's timestamps)"
        )
    return f"give cameras.{name} fps or timestamps"


def _need_timestamps(config: RigRunConfig, trajectories: dict[str, Trajectory]) -> None:
    for name, t in trajectories.items():
        if not t.has_timestamps:
            raise InputError(
                f"estimate_time_offset: camera {name}'s trajectory has no timestamps "
                f"({t.format}); give trajectories with times",
                path=config.path,
            )
        if t.time_unit != "s":
            raise InputError(
                f"estimate_time_offset: camera {name}'s times are frame numbers, not "
                f"seconds; {time_advice(config, name)}",
                path=config.path,
            )


def clock_of(config: RigRunConfig, cameras: Iterable[str]) -> str:
    """The camera whose clock a recording's offsets are counted from: the reference camera
    when the recording saw it, else its camera nearest the reference in the tree."""
    here = set(cameras)
    order = [config.reference_camera] + [s.target for s in config.topology.tree_order()]
    return next(c for c in order if c in here)


def rig_time_offsets(
    config: RigRunConfig,
    trajectories: dict[str, Trajectory],
    priors: dict[str, EdgePrior],
    recording: RigRecordingSpec | None = None,
) -> tuple[dict[str, tuple[float, float]], list[str]]:
    """Every camera's clock offset to its recording's clock (:func:`clock_of`; seconds, with
    its std), each joint the recording moves estimated on its two cameras
    (:func:`acs_cli.core.time_offset.estimate_time_offset`) and added along the tree; and
    warnings (prefixed with the recording's name in a config of several)."""
    _need_timestamps(config, trajectories)
    rec = recording if recording is not None else config.recordings[config.reference_recording]
    root = clock_of(config, trajectories)
    offsets = {root: (0.0, 0.0)}
    notes = []
    shared = rec.shared_world
    for step in config.topology.tree_order():
        j = step.joint
        p, q = j.between
        # the steps away from the reference: within the recording, away from its clock's
        # camera (the recording's camera nearest the reference), once it is reached
        if q not in trajectories or p not in trajectories or step.source not in offsets:
            continue
        if j.name in rec.fixed_joints:
            continue
        tp, tq = trajectories[p], trajectories[q]
        try:
            off = estimate_time_offset(
                tp.timestamps, tp.T_world_cam, tq.timestamps, tq.T_world_cam,
                _edge_fit(config, j, priors, shared), config.max_offset,
            )  # fmt: skip
        except DegenerateMotionError as exc:
            raise DegenerateMotionError(f"joint {j.name}: {exc.message}") from None
        if off.at_limit:
            notes.append(
                f"joint {j.name}: the time offset {off.offset_s:+.4f} s lies at the edge of the "
                f"range searched (+-{config.max_offset:g} s); set a larger max_offset"
            )
        d = off.offset_s if step.forward else -off.offset_s  # target's clock - source's
        base, var = offsets[step.source]
        offsets[step.target] = (base + d, float(np.sqrt(var**2 + off.std_s**2)))
    lost = [c for c in trajectories if c not in offsets]
    if lost:
        raise InputError(
            f"estimate_time_offset: recording {rec.name}'s camera(s) {', '.join(lost)} are "
            f"not joined to {root} by a joint it moves: their clocks cannot be related",
            path=config.path,
        )
    notes.append(
        f"every camera's poses are interpolated (SE(3) splines) at {root}'s times plus its "
        "clock offset; no bundle adjustment on the corners"
    )
    return offsets, notes


def tracks_with_offsets(
    config: RigRunConfig,
    trajectories: dict[str, Trajectory],
    offsets: dict[str, tuple[float, float]],
) -> tuple[dict[str, CameraTrack], np.ndarray, dict[str, np.ndarray]]:
    """Every camera on its recording's clock camera's timeline (:func:`clock_of`: the
    reference camera when the recording saw it), interpolated at its clock's times
    (``t + offset``): tracks, the timeline, and rows (-1: interpolated, no measured row).

    The timeline is the clock camera's instants from the first to the last that every
    camera covers (so that ``reference.frame: 0`` is the first instant all cameras share).
    """
    root = clock_of(config, trajectories)
    ref = trajectories[root]
    poses: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, t in trajectories.items():
        if name == root:
            poses[name] = (t.T_world_cam.copy(), np.ones(len(t), bool))
            continue
        interp = PoseInterpolator(t.timestamps, t.T_world_cam)
        query = ref.timestamps + offsets[name][0]
        valid = interp.valid(query)
        T = np.broadcast_to(np.eye(4), (query.size, 4, 4)).copy()
        T[valid] = interp(query[valid])
        poses[name] = (T, valid)
    every = np.flatnonzero(np.all([v for _, v in poses.values()], axis=0))
    if every.size == 0:
        raise DegenerateMotionError(
            "once their clocks are aligned, the cameras share no instant: record them together"
        )
    span = slice(int(every[0]), int(every[-1]) + 1)
    tracks = {
        name: CameraTrack(T[span], v[span], config.cameras[name].unknown_scale)
        for name, (T, v) in poses.items()
    }
    rows = np.arange(len(ref))[span]
    index = {name: rows if name == root else np.full(rows.size, -1) for name in trajectories}
    return tracks, ref.timestamps[span], index


def rig_synchronisation(
    config: RigRunConfig,
    trajectories: dict[str, Trajectory],
    priors: dict[str, EdgePrior],
    recording: RigRecordingSpec | None = None,
) -> list[str]:
    """Warnings for joints whose cameras fit clearly better with one clock shifted by a
    frame (:func:`acs_cli.core.time_offset.synchronisation_check`; whole frames only, three
    solves of the joint per joint, to keep it cheap)."""
    if config.pair_by == "index" or not all(
        t.has_timestamps and t.time_unit == "s" for t in trajectories.values()
    ):
        return []
    out = []
    rec = recording if recording is not None else config.recordings[config.reference_recording]
    for j in config.topology.joints:
        p, q = j.between
        if p not in trajectories or q not in trajectories or j.name in rec.fixed_joints:
            continue
        tp, tq = trajectories[p], trajectories[q]
        found = synchronisation_check(
            tp.timestamps, tp.T_world_cam, tq.timestamps, tq.T_world_cam,
            _edge_fit(config, j, priors, rec.shared_world), steps=(-1.0, 1.0),
        )  # fmt: skip
        if found is not None:
            out.append(
                f"joint {j.name}: shifting {q}'s timestamps by {1e3 * found[0]:+.1f} ms makes "
                f"its residual {100 * (1 - found[1]):.0f}% smaller: {p} and {q} are probably "
                "not synchronised; set estimate_time_offset: true"
            )
    return out


def rig_bundle(
    config: RigRunConfig,
    files: dict[str, PosesArtifact],
    trajectories: dict[str, Trajectory],
    index: dict[str, np.ndarray],
    est: RigEstimate,
    turned: dict[str, FloatArray] | None = None,
    priors: dict[str, EdgePrior] | None = None,
) -> tuple[RigEstimate, dict[str, BundleSection], list[str]]:
    """Refine a rig on its corners when at least one camera's poses carry them (poses NPZs
    of ``acscal poses``): the estimate, each camera's bundle section, and warnings.
    ``turned``: cameras whose trajectory was brought to another's labelling of a shared
    board by a half turn ``F`` (:func:`shared_board_orders`): their corners' board points
    are turned with it.

    The other bodies (a robot's flange, a motion-capture segment, an INS: poses without
    corners) enter the bundle with their measured poses and their own fitted noise levels.
    The joints known beforehand (``priors``: the config's ``position_in`` and fixed-joint
    sessions, :func:`_priors`, in metres) are fused with the corners as the pose-based solve
    fuses them. A rig whose bundle adjustment fails keeps the pose-based estimate, with a
    warning.
    """
    views: dict[str, CameraViews] = {}
    without: list[str] = []
    notes: list[str] = []
    sources: dict[str, CornerViews] = {}
    n = est.cameras[config.reference_camera].poses_in_reference_world.shape[0]
    # the recordings whose frames the bundle adjusts: one that holds a joint still gives it
    # its prior and no frames (as in the pose-based solve), and one that has no world in the
    # estimate (no joint it moves, e.g. of one body) none either
    named = {w.recording for w in est.worlds}
    moving = [r for r in config.recordings.values() if not r.fixed_joints and r.name in named]
    if config.reference_recording not in {r.name for r in moving}:
        return est, {}, ["no bundle adjustment of the rig: the reference recording "
                         f"{config.reference_recording} holds joint(s) "
                         f"{', '.join(config.recording_of_reference().fixed_joints)} still, "
                         "and such a recording's frames stay out of the bundle"]  # fmt: skip
    labels: dict[str, list[str]] = {}  # each body's labels, one per recording adjusted
    for rec in moving:
        for c in rec.cameras:
            labels.setdefault(c, []).append(label(config, rec.name, c))
    for name, labs in labels.items():
        got: dict[str, CornerViews] = {}
        for lab in labs:
            try:
                one, warning = corner_views(files[lab], len(trajectories[lab]))
            except InputError as exc:  # unreadable corners or intrinsics: the poses serve
                one, warning = None, f"its corners cannot be used ({exc})"
            if warning:
                notes.append(f"camera {lab}: {warning}")
            if one is not None:
                got[lab] = one
        if len(got) < len(labs):
            if got:
                notes.append(
                    f"camera {name}: corners in some recordings only; its poses enter the bundle"
                )
            without.append(name)
            continue
        boards = [
            se3.transform_points(turned[lab], g.board_points)
            if turned and lab in turned
            else g.board_points
            for lab, g in got.items()
        ]
        first = next(iter(got.values()))
        if any(b.shape != boards[0].shape or not np.allclose(b, boards[0]) for b in boards):
            return est, {}, [*notes, "no bundle adjustment of the rig: camera "
                             f"{name} saw different boards (or board orders) in its "
                             "recordings"]  # fmt: skip
        models = {g.model for g in got.values()}
        if len(models) > 1:  # one camera, one model: the bundle fits one set of intrinsics
            return est, {}, [*notes, f"no bundle adjustment of the rig: camera {name}'s "
                             "recordings were posed with different camera models ("
                             + ", ".join(f"{g.model} in {lab}" for lab, g in got.items())
                             + "); calibrate it in one model"]  # fmt: skip
        corners = np.full((n, *first.corners.shape[1:]), np.nan)  # NaN: not seen
        for lab, g in got.items():
            rows = index[lab]
            valid = rows >= 0
            corners[valid] = g.corners[rows[valid]]
        ok = np.asarray(np.isfinite(corners).all(axis=2))
        views[name] = CameraViews(corners, ok, boards[0], first.intrinsics, first.model)
        sources[name] = first
    if not views:
        return est, {}, notes
    unknown = [c for c in config.topology.cameras if config.cameras[c].unknown_scale]
    if unknown:
        return est, {}, [*notes, "no bundle adjustment of the rig: camera(s) "
                         f"{', '.join(unknown)} are configured with scale: unknown, but board "
                         "corners are metric"]  # fmt: skip
    poses: dict[str, CameraTrack] = {}  # the bodies without corners: their measured poses
    for name in without:
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        valid = np.zeros(n, bool)
        for lab in labels[name]:
            rows = index[lab]
            at = rows >= 0
            T[at] = trajectories[lab].T_world_cam[rows[at]]
            valid |= at
        poses[name] = CameraTrack(T, valid)
    # the frames of the recordings adjusted that every joint its recording moves kept
    recs = est.recordings
    of = np.zeros(n, int) if recs is None else recs.of_frame
    use = np.ones(n, bool)
    for i, spec in enumerate(config.recordings.values()):
        here = of == i
        if spec.name not in {r.name for r in moving}:
            use &= ~here
        for e in est.edges.values():
            if set(e.joint.between) <= set(spec.cameras):
                inl = np.zeros(n, bool)
                inl[e.inliers] = True
                use &= inl | ~here
    mask, thinned = bundle_frames(use, est.reference_frame)
    if thinned:
        notes.append(thinned)
    if not mask[est.reference_frame]:
        return est, {}, [*notes, "no bundle adjustment of the rig: every camera must see its "
                         "board at the reference instant, and no joint reject it"]  # fmt: skip
    try:
        ba = bundle_adjust_rig(
            config.topology, views, est, np.flatnonzero(mask), poses, priors=priors
        )
    except (DegenerateMotionError, InputError) as exc:  # e.g. a recording in two parts
        return est, {}, [*notes, f"no bundle adjustment of the rig: {exc.message}; the "
                         "pose-based estimate is kept"]  # fmt: skip
    if not ba.success:
        return est, {}, [*notes, "the rig's bundle adjustment did not converge; the "
                         "pose-based estimate is kept"]  # fmt: skip
    sections = rig_sections({c: sources[c] for c in config.topology.cameras if c in views}, ba)
    return ba.estimate, sections, [*notes, *held_note(ba, "the rig's bundle adjustment")]


#: Folder (beside rig.yaml) of every camera's and joint's trajectory in one frame.
TRAJECTORY_DIR = "trajectories"


def trajectories_from_rig(
    rig: RigArtifact, trajectories: dict[str, Trajectory]
) -> dict[str, tuple[np.ndarray, FloatArray]]:
    """Every camera's and every ball or hinge joint's poses in the reference camera's frame
    at the reference instant, from ``rig.yaml`` and each camera's own trajectory.

    Each measured pose is mapped as it is, the reference instant's too (the run's own
    ``trajectories/`` hold there the poses corrected by the joint constraints, which
    ``T_cam_ref`` reports: they differ by the pose noise; after a bundle adjustment they
    hold its per-frame fit at every instant it adjusted, which needs the corners).

    Returns
    -------
    dict
        Name to ``(times (n,), T_ref_x (n, 4, 4))``; a joint has its point and the
        orientation of its first camera, at that camera's times.

    Raises
    ------
    InputError
        A camera without ``T_ref_world`` (a rig.yaml older than this) or without poses.
    """
    out: dict[str, tuple[np.ndarray, FloatArray]] = {}
    for c, cam in rig.cameras.items():
        if cam.T_cam_ref is None:  # seen only in another recording: not in this frame
            continue
        if cam.T_ref_world is None:
            raise InputError(
                f"cameras.{c}.T_ref_world is missing: rerun acscal run to record it",
                path=rig.source,
            )
        if c not in trajectories:
            raise InputError(f"no trajectory for camera {c} (--poses {c}=FILE)")
        t = trajectories[c]
        T = t.T_world_cam.copy()
        if cam.invert:  # the file holds T_cam_world (rig.yaml records it)
            T = se3.invert_transforms(T)
        T[:, :3, 3] *= cam.scale
        out[c] = (t.timestamps, cam.T_ref_world @ T)
    for name, j in rig.joints.items():
        if not j.model.has_point or j.between[0] not in out:
            continue
        p = j.between[0]
        times, T = out[p]
        J = T.copy()
        J[:, :3, 3] = se3.transform_points(T, j.position_in[p])
        out[name] = (times, J)
    return out


#: Poses fit a rig's calibration when each ball or hinge joint's point, as its two bodies
#: carry it, is at most this many times the calibration's residual RMS apart (median over the
#: instants; plus 1% of the joint's distance from the bodies' origins).
POSES_FIT_FACTOR = 5.0


def check_poses_fit_rig(rig: RigArtifact, paths: dict[str, tuple[np.ndarray, FloatArray]]) -> None:
    """Refuse poses that are not in the worlds ``rig.yaml`` calibrated.

    :func:`trajectories_from_rig` maps each camera's poses by the calibration's
    ``T_ref_world``: right for the calibration's own recording, silently wrong (metres off)
    for another session of the same rig, whose cameras' worlds differ. There the joints come
    apart: each ball or hinge joint's point as its two bodies carry it (``paths``) is compared
    over their common instants with the calibration's residual (:data:`POSES_FIT_FACTOR`).

    Raises
    ------
    InputError
        A joint's bodies put its point further apart than that.
    """
    for name, j in rig.joints.items():
        p, q = j.between
        if not j.model.has_point or p not in paths or q not in paths:
            continue
        (tp, Tp), (tq, Tq) = paths[p], paths[q]
        common, ip, iq = np.intersect1d(tp, tq, return_indices=True)
        if common.size == 0:
            continue
        o_p, o_q = j.position_in[p], j.position_in[q]
        gap = np.linalg.norm(
            se3.transform_points(Tp[ip], o_p) - se3.transform_points(Tq[iq], o_q), axis=1
        )
        median = float(np.median(gap))
        reach = max(float(np.linalg.norm(o_p)), float(np.linalg.norm(o_q)))
        if median > POSES_FIT_FACTOR * j.residual_rms + 0.01 * reach:
            raise InputError(
                f"joint {name}: in these poses {p} and {q} put it {median:.3g} "
                f"{rig.length_unit} apart (median over {common.size} instants), against a "
                f"residual of {j.residual_rms:.3g} in the calibration: the poses are not in "
                "the worlds it calibrated (--poses takes files of the calibration's own "
                "recording; calibrate another recording with acscal run)",
                path=rig.source,
            )


def joint_residuals(est: RigEstimate, times: np.ndarray) -> list[JointResiduals]:
    """Every joint's residual per frame, one series per joint and recording: the norms of
    its residual rows (:attr:`EdgeEstimate.frame_residuals
    <acs_cli.core.rig_solve.EdgeEstimate.frame_residuals>`, the pose-based solve's, kept
    through a bundle adjustment), rotations in degrees, at ``times`` ``(n,)`` (the rig's
    timeline) of the edge's frames, each marked used or rejected."""
    recs = est.recordings or Recordings.single(times.size)
    out: list[JointResiduals] = []
    for name, e in est.edges.items():
        if not e.frames.size:
            continue
        used = np.isin(e.frames, e.inliers)
        norms = {k: np.linalg.norm(v, axis=1) for k, v in e.frame_residuals.items()}
        if "rot" in norms:
            norms["rot"] = np.degrees(norms["rot"])
        of = recs.of_frame[e.frames]
        for i, rname in enumerate(recs.names):
            sel = of == i
            if sel.any():
                vals = {k: v[sel] for k, v in norms.items()}
                out.append(JointResiduals(name, rname, times[e.frames[sel]], used[sel], vals))
    return out


def write_rig_trajectories(
    est: RigEstimate, tracks: dict[str, CameraTrack], times: np.ndarray, folder: Path
) -> list[Path]:
    """Write ``<camera>.tum`` and ``<joint>.tum`` into ``folder``: the whole rig over time.

    Every pose is ``T_ref_x``: in the reference camera's frame at the reference instant
    (reference units), as ``T_world_cam`` TUM rows whose "world" is that frame. A joint's
    file holds its centre (ball) or hinge point with the orientation of the edge's first
    camera; frames where a camera has no pose are left out. After a bundle adjustment the
    instants it adjusted (``est.bundle_frames``) hold its per-frame fit on the corners, the
    others the measured poses mapped by the refined calibration; a comment line under the
    header says which rows are which.
    """
    ref = est.topology.reference
    G_ref_k = est.cameras[ref].poses_in_reference_world[est.reference_frame]
    T_ref_w = se3.invert_transforms(G_ref_k)
    written: list[Path] = []
    fitted = np.zeros(times.size, bool)
    fitted[est.bundle_frames] = True

    def note(ok: np.ndarray) -> str | None:
        """Which rows are the bundle's fit (None without a bundle adjustment)."""
        if not fitted[ok].any():
            return None
        if fitted[ok].all():
            return "every pose: the rig's bundle adjustment's per-frame fit on the corners"
        return (
            f"{int(fitted[ok].sum())} of {int(ok.sum())} poses are the rig's bundle "
            "adjustment's per-frame fit on the corners, those at t = "
            + " ".join(f"{t:.9f}" for t in times[ok & fitted])
            + "; the others are measured poses mapped by the refined calibration"
        )

    # the reference recording's instants: the only ones in the reference camera's frame
    recs = est.recordings
    here = (
        np.ones(times.size, bool)
        if recs is None
        else recs.of_frame == recs.of_frame[est.reference_frame]
    )
    for c, e in est.cameras.items():
        ok = tracks[c].valid & here
        if e.in_reference_world.size:  # not where its world is not the reference's
            ok &= e.in_reference_world
        if not ok.any():
            continue
        path = folder / f"{c}.tum"
        write_tum(path, times[ok], T_ref_w @ e.poses_in_reference_world[ok], note=note(ok))
        written.append(path)
    for name, edge in est.edges.items():
        if not edge.position_in:
            continue
        p, q = edge.joint.between
        ok = tracks[p].valid & tracks[q].valid & here
        for c in (p, q):
            if est.cameras[c].in_reference_world.size:
                ok &= est.cameras[c].in_reference_world
        if not ok.any():
            continue
        G = est.cameras[p].poses_in_reference_world[ok]
        T = G.copy()
        T[:, :3, 3] = se3.transform_points(G, edge.position_in[p])
        path = folder / f"{name}.tum"
        write_tum(path, times[ok], T_ref_w @ T, note=note(ok))
        written.append(path)
    return written
