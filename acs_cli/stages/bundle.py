"""Bundle adjustment on the detected corners, for the joint and relpose stages.

A poses NPZ written by ``acscal poses`` carries its corners, its board and the intrinsics
file it was solved with. When both are there, the stages refine their estimate by the
maximum-likelihood fit on the pixels: the fixed-joint motion per camera
(:mod:`acs_cli.core.bundle`), the overlap's two-body rig (:mod:`acs_cli.core.rig_bundle`) and
the general motion for the two cameras together. Each function
returns the refined quantities, the artifact's ``bundle_adjustment`` section, and warnings;
a trajectory without corners (TUM, KITTI, COLMAP) is simply not refined.

Each camera keeps the model its intrinsics file was calibrated with (pinhole, rational or
fisheye); a corner a frame did not see is NaN, so a partial view of a target counts. A
refined distortion the corners do not determine
(:func:`acs_cli.core.intrinsics.degenerate_distortion`) is warned about (fixed joint) or held
(the two-body rig's bundle holds both cameras' intrinsics, :func:`held_note`). The
fixed-joint adjustment judges
again, on their corners, the frames the pose-based fit rejected (:func:`readmit_frames`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from acs_cli.core.bundle import MIN_FRAME_CORNERS, camera_matrix, intrinsics_vector
from acs_cli.core.camera_models import camera_model
from acs_cli.core.intrinsics import degenerate_distortion, outlier_views
from acs_cli.core.joint import JointEstimate
from acs_cli.core.overlap import JOINT
from acs_cli.core.relpose import (
    TWO_BODY_JOINT,
    JointPrior,
    RelposeEstimate,
    prior_for_rig,
    relpose_refined_by,
)
from acs_cli.core.rig import RigJoint, RigTopology, rig_topology
from acs_cli.core.rig_bundle import (
    CameraViews,
    FixedJointBundle,
    RigBundle,
    bundle_adjust_fixed_joint,
    bundle_adjust_rig,
)
from acs_cli.core.rig_solve import (
    TEST_SETTLED_NOISE,
    CameraTrack,
    EdgePrior,
    Recordings,
    RigEstimate,
    estimate_rig,
)
from acs_cli.errors import DegenerateMotionError, InputError
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.joint import BundleSection
from acs_cli.io.poses import PosesArtifact
from acs_cli.stages.common import PairedTrajectories

__all__ = [
    "MAX_BUNDLE_FRAMES",
    "CornerViews",
    "board_order_residuals",
    "bundle_fixed_joint",
    "bundle_general",
    "bundle_overlap",
    "bundle_section",
    "corner_views",
    "degenerate_warning",
    "held_note",
    "readmit_frames",
    "rig_sections",
    "shared_board_flip",
]

#: Most frames a bundle adjustment takes (its dense Jacobian grows with their square:
#: about 160 MB for 100 frames of two 9x6 boards); longer recordings use this many,
#: evenly spaced, and say so.
MAX_BUNDLE_FRAMES = 100


def bundle_frames(used: np.ndarray, keep: int | None = None) -> tuple[np.ndarray, str | None]:
    """The frames to adjust: ``used`` (a mask), thinned evenly to :data:`MAX_BUNDLE_FRAMES`
    (always keeping frame ``keep``), and a warning when thinned."""
    idx = np.flatnonzero(used)
    if idx.size <= MAX_BUNDLE_FRAMES:
        return used, None
    pick = idx[np.round(np.linspace(0, idx.size - 1, MAX_BUNDLE_FRAMES)).astype(int)]
    if keep is not None and keep not in pick:
        pick[np.argmin(np.abs(pick - keep))] = keep
    out = np.zeros_like(used)
    out[pick] = True
    return out, (
        f"bundle adjustment on {MAX_BUNDLE_FRAMES} of {idx.size} frames (evenly spaced), "
        "to bound its memory"
    )


@dataclass(frozen=True)
class CornerViews:
    """One camera's corners with the intrinsics they were posed with.

    Attributes
    ----------
    corners : ndarray, shape (n, m, 2)
        Pixels, one row of corners per pose of the trajectory; NaN where not seen.
    board_points : ndarray, shape (m, 3)
        Metres, in the board's frame (every corner of the target).
    intrinsics : ndarray, shape (p,)
        Named by the model's ``names`` (``fx fy cx cy k1 k2 p1 p2 k3`` for pinhole).
    intrinsics_file : Path
    model : str
        The intrinsics file's camera model.
    intrinsics_std : ndarray, shape (p,), or None
        The file's one-sigma intrinsics (named as ``intrinsics``), when it gives them all.
    """

    corners: np.ndarray
    board_points: np.ndarray
    intrinsics: np.ndarray
    intrinsics_file: Path
    model: str = "pinhole"
    intrinsics_std: np.ndarray | None = None


def _resolve(recorded: str, poses: Path) -> Path | None:
    """The intrinsics file as recorded, or by its name beside the poses (a moved run)."""
    for candidate in (Path(recorded), poses.parent / Path(recorded).name):
        if candidate.is_file():
            return candidate
    return None


def corner_views(poses: PosesArtifact, n_poses: int) -> tuple[CornerViews | None, str | None]:
    """The corners behind a trajectory with the intrinsics they were posed with (the
    intrinsics file read), or why there are none usable.

    Returns ``(views, None)``, ``(None, warning)`` or ``(None, None)`` for poses without
    corners (a trajectory format that never carries them).
    """
    corners, board, recorded = poses.corners, poses.board_points, poses.intrinsics_file
    if corners is None or board is None:
        return None, None
    where = Path(poses.source or "poses")
    if corners.shape[0] != n_poses:
        return None, f"{where.name}: corners and poses disagree; no bundle adjustment"
    path = None if recorded is None else _resolve(recorded, where)
    if path is None:
        return None, f"{where.name}: its intrinsics file was not found; no bundle adjustment"
    intr = IntrinsicsArtifact.load(path)
    vec = intrinsics_vector(intr.camera_matrix, intr.distortion, intr.model)
    sd = intr.std or {}
    std = [sd.get(k) for k in ("fx", "fy", "cx", "cy")] + list(sd.get("distortion") or [])
    ok = len(std) == vec.size and all(isinstance(v, (int, float)) for v in std)
    given = np.asarray(std, dtype=float) if ok else None
    return CornerViews(corners, board, vec, path, intr.model, given), None


def bundle_section(
    views: CornerViews,
    intr: np.ndarray,
    std: np.ndarray,
    rms: float,
    sigma: float,
    n: int,
    held: bool = False,
) -> BundleSection:
    """The artifact's section of one camera's bundle adjustment (parameters named by its
    model); ``held``: the intrinsics were held, and the std reported is the file's (or none)."""
    sd = views.intrinsics_std if held else std
    return BundleSection(
        intrinsics_file=str(views.intrinsics_file),
        rms_px=float(rms),
        sigma_px=float(sigma),
        frames=n,
        camera_matrix=camera_matrix(intr),
        distortion=np.asarray(intr[4:], dtype=float),
        intrinsics_std={}
        if sd is None
        else dict(zip(camera_model(views.model).names, sd.tolist(), strict=True)),
        model=views.model,
        intrinsics_held=held,
    )


def rig_sections(views: dict[str, CornerViews], ba: RigBundle) -> dict[str, BundleSection]:
    """Each camera's section of a rig's bundle adjustment ``ba``, in ``views``' order."""
    held = ba.intrinsics_held is not None
    return {  # each camera's frames: those its recordings saw it in
        c: bundle_section(v, ba.intrinsics[c], ba.intrinsics_std[c], ba.rms_px[c], ba.sigma_px,
                          int(np.count_nonzero(ba.per_frame_rms_px[c])), held)
        for c, v in views.items()
    }  # fmt: skip


def held_note(ba: RigBundle, what: str) -> list[str]:
    """``[note]`` when the rig's bundle adjustment ``ba`` held every camera's intrinsics."""
    if ba.intrinsics_held is None:
        return []
    return [f"{what} held every camera's intrinsics ({ba.intrinsics_held}): the rig is fitted "
            "on the corners with each camera's own calibration"]  # fmt: skip


def degenerate_warning(
    cam: str, model: str, intrinsics: np.ndarray, covariance: np.ndarray
) -> list[str]:
    """``[warning]`` when the bundle's refined distortion of camera ``cam`` is degenerate
    (:func:`acs_cli.core.intrinsics.degenerate_distortion` on the intrinsics ``(p,)`` and
    their covariance ``(p, p)``), else ``[]``."""
    found = degenerate_distortion(model, intrinsics[4:], covariance[4:, 4:])
    return [f"camera {cam} after the bundle adjustment: {found}"] if found else []


def bundle_fixed_joint(
    poses: PosesArtifact, T_w_c: np.ndarray, est: JointEstimate, cam: str
) -> tuple[JointEstimate, BundleSection | None, list[str]]:
    """Refine camera ``cam``'s joint (and intrinsics) on its corners, when they are there."""
    views, warning = corner_views(poses, T_w_c.shape[0])
    o0 = est.position_in_a if cam == "a" else est.position_in_b
    if views is None or o0 is None:
        return est, None, [warning] if warning else []
    inl, thinned = bundle_frames(est.inliers[cam])
    notes = [thinned] if thinned else []

    def adjust(frames: np.ndarray) -> FixedJointBundle:
        return bundle_adjust_fixed_joint(
            views.corners[frames],
            None,  # every corner seen (NaN: not seen)
            views.board_points,
            views.intrinsics,
            T_w_c[frames],
            o0,
            est.position_in_world[cam],
            model=views.model,
        )

    ba = adjust(inl)
    if not ba.success:
        return est, None, [*notes, f"camera {cam.upper()}: the bundle adjustment did not "
                           "converge; the pose-based estimate is kept"]  # fmt: skip
    if thinned is None:
        ba, inl = readmit_frames(adjust, ba, inl, views.corners)
    notes += degenerate_warning(cam.upper(), ba.model, ba.intrinsics, ba.intrinsics_covariance)
    cov = ba.joint_covariance
    inliers = {**est.inliers, cam: inl}
    correlated = {**est.correlated, cam: ba.correlated}
    refined = (
        replace(est, position_in_a=ba.joint_in_cam, covariance_a=cov, inliers=inliers)
        if cam == "a"
        else replace(est, position_in_b=ba.joint_in_cam, covariance_b=cov, inliers=inliers)
    )
    refined = replace(refined, correlated=correlated)
    refined.position_in_world[cam] = ba.joint_in_world
    section = bundle_section(
        views, ba.intrinsics, ba.intrinsics_std, ba.rms_px, ba.sigma_px, int(inl.sum())
    )
    return refined, section, notes


def readmit_frames(
    adjust: Callable[[np.ndarray], FixedJointBundle],
    ba: FixedJointBundle,
    used: np.ndarray,
    corners: np.ndarray,
) -> tuple[FixedJointBundle, np.ndarray]:
    """Judge again, on their corners, the frames the pose-based fit rejected.

    A pose from a partial view of a target (a few corners in a corner of the image) is
    noisier than one from a whole board, so the pose-based estimate, which gives every
    frame one noise level, may reject it although its corners are as good as any. Every
    rejected frame with at least :data:`acs_cli.core.bundle.MIN_FRAME_CORNERS` corners is
    adjusted with the others; those whose reprojection RMS is then an outlier
    (:func:`acs_cli.core.intrinsics.outlier_views`) stay out, the rest are used.

    Parameters
    ----------
    adjust : callable
        The bundle adjustment of the frames a mask ``(n,)`` selects.
    ba : FixedJointBundle
        ``adjust(used)``.
    used : ndarray of bool, shape (n,)
        The frames the pose-based fit kept.
    corners : ndarray, shape (n, m, 2)
        Every frame's corners (NaN: not seen).

    Returns
    -------
    FixedJointBundle, ndarray of bool
        The adjustment and the frames it used (``ba`` and ``used`` when none came back).
    """
    seen = np.isfinite(corners).all(axis=2).sum(axis=1) >= MIN_FRAME_CORNERS
    candidates = ~used & seen
    if not candidates.any():
        return ba, used
    trial = used | candidates
    ba_all = adjust(trial)
    if not ba_all.success:
        return ba, used
    idx = np.flatnonzero(trial)
    back = candidates.copy()
    back[idx[outlier_views(ba_all.per_frame_rms_px)]] = False
    if not back.any():
        return ba, used
    if np.array_equal(back, candidates):
        return ba_all, trial
    again = adjust(used | back)
    return (again, used | back) if again.success else (ba, used)


def shared_board_flip(poses: tuple[PosesArtifact, PosesArtifact]) -> np.ndarray | None:
    """``T_w1_w2`` between the two corner orders of one board both cameras saw, or None.

    A board that looks the same turned by 180 degrees about its normal (any checkerboard)
    can be labelled in two orders; two cameras that see it at very different rolls may
    pick different ones, and then their "one world" differs by this transform (see
    :func:`acs_cli.core.pnp.reversed_order_transform`). None unless both poses carry the
    corners of the same, symmetric checkerboard (a target's corners are identified).
    """
    X, Y = poses[0].board_points, poses[1].board_points  # None: no corners
    if X is None or Y is None or X.shape != Y.shape or not np.allclose(X, Y):
        return None
    if any("target" in p.header for p in poses):
        return None  # an AprilGrid or ChArUco: every corner identified, one labelling only
    F = np.diag([-1.0, -1.0, 1.0, 1.0])
    F[:3, 3] = X[0] + X[-1]
    if not np.allclose(X @ F[:3, :3].T + F[:3, 3], X[::-1], atol=1e-9):
        return None
    return F


def board_order_residuals(
    joint: RigJoint, first: str, tracks: dict[str, CameraTrack], F: np.ndarray
) -> tuple[float, float]:
    """How ``joint`` fits with its other camera's poses as labelled and turned to
    ``first``'s labelling of a shared board by ``F`` (:func:`shared_board_flip`).

    Both cameras' poses are in one world; each labelling is solved as the two-body rig of
    the joint (:func:`acs_cli.core.rig_solve.estimate_rig`, one shared world, no outlier
    rejection). The labelling that fits with less than half the other's residual is the
    board's one order (the wrong one is off by the board's size, not by noise).

    Returns
    -------
    rms_as_labelled, rms_turned : float
        The joint's residual RMS, ``inf`` where the rig refuses.
    """
    second = joint.other(first)
    sub = rig_topology([first, second], [(joint.name, [first, second], joint.type)], first)
    tb = tracks[second]
    flipped = CameraTrack(
        np.where(tb.valid[:, None, None], F @ tb.T_w_c, tb.T_w_c), tb.valid, tb.unknown_scale
    )
    n = tb.valid.size
    rms = []
    for t in (tb, flipped):
        try:
            est = estimate_rig(
                sub, {first: tracks[first], second: t}, reject_outliers=False,
                recordings=Recordings.single(n, True), noise_tolerance=TEST_SETTLED_NOISE,
            )  # fmt: skip
            rms.append(est.edges[joint.name].residual_rms)
        except (DegenerateMotionError, InputError):
            rms.append(np.inf)
    return rms[0], rms[1]


def _pair_views(
    poses: tuple[PosesArtifact, PosesArtifact], pair: PairedTrajectories, reverse_b: bool = False
) -> tuple[tuple[CornerViews, CornerViews] | None, list[str]]:
    """Both cameras' corners, reduced to the paired frames (B's in reversed order when its
    board labelling was turned round to A's)."""
    p = pair.pairing
    va, wa = corner_views(poses[0], len(p.idx_a) + p.unpaired_a)
    vb, wb = corner_views(poses[1], len(p.idx_b) + p.unpaired_b)
    warnings = [w for w in (wa, wb) if w]
    if va is None or vb is None:
        if (va is None) != (vb is None) and not warnings:
            warnings.append("only one camera's poses carry corners; no bundle adjustment")
        return None, warnings
    return (
        replace(va, corners=va.corners[p.idx_a]),
        replace(vb, corners=vb.corners[p.idx_b][:, ::-1] if reverse_b else vb.corners[p.idx_b]),
    ), warnings


def bundle_overlap(
    poses: tuple[PosesArtifact, PosesArtifact],
    pair: PairedTrajectories,
    est: RigEstimate,
    reverse_b: bool = False,
) -> tuple[RigEstimate, dict[str, BundleSection] | None, list[str]]:
    """Refine the overlap's two-body rig (:data:`acs_cli.core.overlap.OVERLAP_RIG`) on both
    cameras' corners of the shared board (:func:`acs_cli.core.rig_bundle.bundle_adjust_rig`).

    ``pair`` holds the paired poses of the two files (one world: the shared board), ``est``
    the rig solved from them; ``reverse_b``: B's poses were brought to A's labelling of the
    board, so its corners are read in reversed order. The frames are the joint's inliers.
    """
    views, warnings = _pair_views(poses, pair, reverse_b)
    if views is None:
        return est, None, warnings
    if views[0].corners.shape[1] != views[1].corners.shape[1] or not np.allclose(
        views[0].board_points, views[1].board_points
    ):
        return est, None, [*warnings, "the two cameras saw different boards; no bundle "
                           "adjustment (the overlap scenario needs one shared board)"]  # fmt: skip
    return _two_body_bundle(est.topology, JOINT, views, est, None, warnings)


def _two_body_bundle(
    topology: RigTopology,
    joint: str,
    views: tuple[CornerViews, CornerViews],
    est: RigEstimate,
    priors: dict[str, EdgePrior] | None,
    warnings: list[str],
) -> tuple[RigEstimate, dict[str, BundleSection] | None, list[str]]:
    """The two-body rig ``est`` (cameras ``a`` and ``b``) refined on both cameras' corners
    over the joint's inlier frames: the estimate, the sections and the warnings."""
    used = np.zeros(views[0].corners.shape[0], bool)
    used[est.edges[joint].inliers] = True
    if not used[est.reference_frame]:
        return est, None, [*warnings, "the reference frame was rejected as an outlier; no "
                           "bundle adjustment"]  # fmt: skip
    frames, thinned = bundle_frames(used, est.reference_frame)
    warnings = [*warnings, thinned] if thinned else list(warnings)
    cams = {
        c: CameraViews(v.corners, np.isfinite(v.corners).all(axis=2), v.board_points,
                       v.intrinsics, v.model)
        for c, v in zip(("a", "b"), views, strict=True)
    }  # fmt: skip
    try:
        ba = bundle_adjust_rig(topology, cams, est, np.flatnonzero(frames), priors=priors)
    except DegenerateMotionError as exc:
        return est, None, [*warnings, f"no bundle adjustment: {exc.message}; the pose-based "
                           "estimate is kept"]  # fmt: skip
    if not ba.success:
        return est, None, [*warnings, "the bundle adjustment did not converge; the pose-based "
                           "estimate is kept"]  # fmt: skip
    sections = rig_sections(dict(zip(("a", "b"), views, strict=True)), ba)
    return ba.estimate, sections, [*warnings, *held_note(ba, "the bundle adjustment")]


def bundle_general(
    poses: tuple[PosesArtifact, PosesArtifact],
    pair: PairedTrajectories,
    est: RelposeEstimate,
    prior: JointPrior | None,
) -> tuple[RelposeEstimate, dict[str, BundleSection] | None, list[str]]:
    """Refine the general scenario's relative pose and joint on both cameras' corners: the
    two-body rig of :func:`acs_cli.core.relpose.two_body_rig` through the rig's bundle
    adjustment (:func:`acs_cli.core.rig_bundle.bundle_adjust_rig`).

    Each camera sees its own board; the world-A-to-world-B transform is one more unknown.
    A joint from a fixed-joint session (``prior``, metric) is fused with the corners.
    """
    if est.unknown_scale:  # said only where there are corners to adjust
        has = all(p.corners is not None for p in poses)
        return est, None, ["no bundle adjustment under unknown scale (corners are metric)"] * has
    if est.rig is None:
        return est, None, []
    views, warnings = _pair_views(poses, pair)
    if views is None:
        return est, None, warnings
    edge_prior = None if prior is None else prior_for_rig(prior, unknown_scale=False)
    priors = None if edge_prior is None else {TWO_BODY_JOINT: edge_prior}
    rig, sections, warnings = _two_body_bundle(
        est.rig.topology, TWO_BODY_JOINT, views, est.rig, priors, warnings
    )
    if sections is None:
        return est, None, warnings
    return relpose_refined_by(est, rig), sections, warnings
