"""Bundle adjustment of a whole rig on its cameras' board corners.

When every camera of a rig sees a calibration board, the maximum-likelihood calibration
fits the rig's model to the detected corners (pixels) instead of to the poses solved from
them. The model is the kinematic tree itself:

- frame ``i`` has the reference camera's pose in its board's frame, ``G[i]`` (6 unknowns),
  and each joint's articulation: a ball's rotation ``R_p_q[i]`` (3), a hinge's angle
  ``theta[i]`` (1), nothing for a rigid joint;
- each joint has its fixed geometry: a ball's centre ``o_p``, ``o_q`` (the paper's eq. (2):
  ``T_p_q[i] = [R_p_q[i], o_p - R_p_q[i] o_q]``); a hinge's frames ``A`` (its axis ``u_p``
  is ``A``'s third column), ``B`` (``u_q = B^T e_z``) and points ``o_p``, ``o_q`` on the
  axis, with ``R_p_q[i] = A Rz(theta[i]) B``; a rigid joint's ``T_p_q``;
- every camera but the reference sees its own board, whose frame is ``W_c = T_wref_wc`` in
  the reference board's frame (6 unknowns);
- every camera has its intrinsics in its own model (:mod:`acs_cli.core.camera_models`:
  pinhole with ``k3`` held, rational or fisheye).

A body of the tree need not be a camera: a robot's flange (poses from its controller), a
motion-capture segment or an INS has poses but no corners. Such a *pose-only* body ``b``
has its world too, ``W_b`` (for a camera on a robot's flange: the robot's base in the
board's frame, the ``Z`` of ``AX = ZB``; the rigid joint between them is ``X``), and its
measured poses ``M_b[i] = T_wb_b[i]`` are measurements of ``W_b^-1 G[i] T_ref_b[i]``: the
residual is ``log(R_M^T R)`` (radians, in the body's frame) and the difference of the
translations (in its world), with the body's own noise levels (one rotation and one
translation sigma) estimated by maximum likelihood: the solve alternates with a variance
component refit (Förstner's: each group's squared residuals over its redundancy, from the
final information) until the levels settle. Every residual is a function of the physical
rig only, so the solution does not depend on how the rig is written down (which body is
the reference, which way round a joint's ``between`` is).

Camera ``c``'s pose is chained along the tree, ``T_ref_c[i]`` (its steps from the reference,
:meth:`acs_cli.core.rig.RigTopology.tree_order`), so a corner ``X`` of its board is at

    x_c = (G[i] T_ref_c[i])^-1 W_c X

and the residual is its projection minus the detected corner (a corner a frame did not see
is NaN, so each frame may see a different part of its board). Gauges are fixed in the
parametrisation: a hinge's frames turn only across its axis, and its point moves only
across the axis (the point nearest camera ``p``'s centre is reported, as
:mod:`acs_cli.core.rig_solve` does). The solve starts from the pose-based rig estimate
(:func:`acs_cli.core.rig_solve.estimate_rig`) and uses the one least-squares engine
(:func:`acs_cli.core.lsq.solve`, Levenberg-Marquardt on the normal equations) with a
sparse Jacobian differenced in groups (:func:`acs_cli.core.lsq.block_jacobian`: the
unknowns of different frames never share a row). Covariances come from the inverse of the
information, scaled by the fitted corner noise (with pose-only bodies: of the whitened
residuals at the fitted noise levels).

Intrinsics and frames: the bundle refines every camera's intrinsics when it has at least
:data:`MIN_INTRINSICS_FRAMES` frames (what a camera's own calibration needs,
:data:`acs_cli.core.intrinsics.MIN_VIEWS`) and the corners determine them (the information
is not singular and no refined distortion is degenerate,
:func:`acs_cli.core.intrinsics.degenerate_distortion`); otherwise it holds them and still
fits the rig on the corners (OpenCV's ``stereoCalibrate`` with ``CALIB_FIX_INTRINSIC`` for
a stereo pair). It takes no fixed number of frames: it refuses (``DegenerateMotionError``)
when its information is singular, an unknown whose information the others explain but a
share :data:`UNDETERMINED_SHARE` (a Cholesky pivot of the information scaled to a unit
diagonal; measured: at most 6e-13 where a ball's centre is undetermined, at least 2e-4 on
the determined rigs of the tests). So a rigid pair seeing one board needs 1 frame, a
hinge 2 and a ball 3 (a joint's articulation at every frame leaves fewer rows for its
centre); in separate worlds each camera's board adds 6 unknowns.

Several recordings (the estimate's :class:`~acs_cli.core.rig_solve.Recordings`): the
joints' geometry and the intrinsics are shared, each (recording, body) has its own board
(its world), and each recording's boards are fixed up to one rigid motion with its frames'
poses ``G[i]``: the gauge holds the reference's world in its recording and, in every other
one, the board of its body nearest the reference in the tree (every board of a shared
world). A recording that did not see the reference body has a virtual ``G[i]`` (the pose
that puts its first body where the estimate has it), and the articulations of the joints a
frame's recording did not see are held by rows of their own. A recording none of whose
frames is adjusted adds no unknowns. A static reference body (``static``, the world of a
joint held still: :func:`bundle_adjust_fixed_joint`) has no pose unknowns.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.sparse

from acs_cli.core import lsq, se3
from acs_cli.core.bundle import check_frame_corners, information, observed
from acs_cli.core.camera_models import camera_model
from acs_cli.core.correlated import (
    NOT_TESTED,
    CorrelatedErrors,
    covariance_with_correlated_errors,
    frame_scores,
)
from acs_cli.core.intrinsics import MIN_VIEWS, degenerate_distortion
from acs_cli.core.joints import JointModel, joint_model
from acs_cli.core.rig import RigJoint, RigTopology, rig_topology
from acs_cli.core.rig_solve import (
    CameraEstimate,
    CameraTrack,
    EdgeEstimate,
    EdgePrior,
    RigEstimate,
    edge_prior_rows,
)
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

__all__ = [
    "MIN_INTRINSICS_FRAMES",
    "PIVOT_RIG",
    "CameraViews",
    "FixedJointBundle",
    "PoseBodyEstimate",
    "PoseBodyFit",
    "RigBundle",
    "RigidEdgeEstimate",
    "bundle_adjust_fixed_joint",
    "bundle_adjust_rig",
]

#: Fewest frames on which the bundle refines the cameras' intrinsics (as many as a camera's
#: own calibration needs); on fewer it holds them.
MIN_INTRINSICS_FRAMES = MIN_VIEWS
#: Noise-level refits (each followed by a solve) with pose-only bodies, at most.
NOISE_ROUNDS = 30
#: The refit noise levels are final when none moves by more than this share (in its log).
NOISE_SETTLED = 1e-5
#: Pose-only noise levels are kept above these (radians, and a share of the body's travel):
#: noiseless poses would otherwise weigh their rows beyond what differences resolve.
NOISE_FLOOR_ROT = 1e-7
NOISE_FLOOR_LENGTH = 1e-7
#: An unknown is undetermined when at most this share of its information at the start is its
#: own (the rest explained by the unknowns before it: a Cholesky pivot of the information
#: scaled to a unit diagonal).
UNDETERMINED_SHARE = 1e-8


@dataclass(frozen=True)
class RigidEdgeEstimate(EdgeEstimate):
    """A rigid joint refined by the bundle: ``T_q_p`` with its covariance ``(6, 6)`` (right
    rotation perturbation of ``R_q_p`` (rad), then ``t_q_p``)."""

    T_q_p_covariance: FloatArray = field(default_factory=lambda: np.zeros((6, 6)))


@dataclass(frozen=True)
class PoseBodyFit:
    """A pose-only body of the bundle (one with poses and no corners).

    Attributes
    ----------
    frames : int
        The frames adjusted.
    sigma_rot_deg, sigma_trans : float
        The fitted noise of its measured poses: per axis, degrees (rotation about the
        body's own axes) and metres (translation in its world).
    rms_rot_deg, rms_trans : float
        RMS of its pose residuals (angle, degrees; distance, metres) over the frames.
    T_world_board : dict of camera to ndarray (4, 4)
        Each corner camera's board frame in this body's world (``T_wb_board``: for a camera
        on a robot's flange, the board in the robot's base, ``Z``).
    T_world_board_covariance : dict of camera to ndarray (6, 6)
        Right rotation perturbation (rad), then translation (m).
    """

    frames: int
    sigma_rot_deg: float
    sigma_trans: float
    rms_rot_deg: float
    rms_trans: float
    T_world_board: dict[str, FloatArray]
    T_world_board_covariance: dict[str, FloatArray]


@dataclass(frozen=True)
class CameraViews:
    """One camera's corners on the rig's timeline.

    Attributes
    ----------
    corners : ndarray, shape (n, m, 2)
        Pixels, one row per instant of the timeline; NaN where a corner was not seen.
    valid : ndarray of bool, shape (n, m)
        Which corners were detected (rows of instants without a pose: all False); only
        finite corners are used whatever it says.
    board_points : ndarray, shape (m, 3)
        The corners in the camera's board frame (metres).
    intrinsics : ndarray, shape (p,)
        Initial intrinsics, named by the model's ``names``.
    model : str
        The camera model (:data:`acs_cli.core.camera_models.CAMERA_MODELS`); its default
        held parameters are held (``k3`` of the pinhole model).
    """

    corners: FloatArray
    valid: np.ndarray
    board_points: FloatArray
    intrinsics: FloatArray
    model: str = "pinhole"


@dataclass(frozen=True)
class PoseBodyEstimate(CameraEstimate):
    """A pose-only body of the bundle's estimate: its pose as any camera's, and its fit."""

    pose_fit: PoseBodyFit | None = None


@dataclass(frozen=True)
class RigBundle:
    """Result of :func:`bundle_adjust_rig`.

    Attributes
    ----------
    estimate : RigEstimate
        The rig with the bundle's ``T_cam_ref`` (and covariances), joints and boards'
        frames. Each body's ``poses_in_reference_world`` ``(n, 4, 4)`` holds at the instants
        adjusted (``bundle_frames``, the same as ``frames``) where its recording saw it the
        bundle's per-frame fit ``G[i] T_ref_c[i]``, and at the others its measured poses
        mapped by its recording's refined board frame, as the pose-based solve maps them. The
        joints' ``residual_rms``, frame counts, inliers and noise stay those of the
        pose-based solve.
    intrinsics, intrinsics_std : dict of camera to ndarray (p,)
        Refined intrinsics (named by the camera's model) and their standard deviations (0
        if held).
    intrinsics_covariance : dict of camera to ndarray (p, p)
        Their covariances (0 rows and columns for held ones).
    rms_px : dict of camera to float
        Reprojection RMS per camera.
    sigma_px : float
        Estimated standard deviation of a corner coordinate.
    frames : ndarray of int
        The instants adjusted (indices into the timeline).
    success : bool
        The solver converged.
    pose_bodies : dict of body to PoseBodyFit
        The bodies that had poses only (empty when every body has corners).
    per_frame_rms_px : dict of camera to ndarray (len(frames),)
        Each camera's reprojection RMS per adjusted frame.
    intrinsics_held : str or None
        Why every camera's intrinsics were held (``intrinsics`` are then the views' own, their
        std and covariance 0), or None when they were refined.
    """

    estimate: RigEstimate
    intrinsics: dict[str, FloatArray]
    intrinsics_std: dict[str, FloatArray]
    intrinsics_covariance: dict[str, FloatArray]
    rms_px: dict[str, float]
    sigma_px: float
    frames: np.ndarray
    success: bool
    pose_bodies: dict[str, PoseBodyFit] = field(default_factory=dict)
    per_frame_rms_px: dict[str, FloatArray] = field(default_factory=dict)
    intrinsics_held: str | None = None


class _Layout:
    """Where each unknown lives: shared ones first, then one block per frame."""

    def __init__(
        self,
        topo: RigTopology,
        n: int,
        free: dict[str, list[int]],
        worlds: list[tuple[int, str]],
        static: bool = False,
    ) -> None:
        k = 0
        self.free = free  # per camera: indices of its refined intrinsics
        self.intr = {}
        for c in topo.cameras:
            if c in free:  # a camera with corners (not a pose-only body)
                self.intr[c] = slice(k, k + len(free[c]))
                k += len(free[c])
        # each (recording, body)'s board (a pose-only body's world) with unknowns: all but
        # each recording's gauge (the reference's world; another recording's first body's)
        self.world: dict[tuple[int, str], slice] = {}
        for w in worlds:
            self.world[w] = slice(k, k + 6)
            k += 6
        self.geom = {}
        for j in topo.joints:
            size = joint_model(j.type).bundle_params  # the joint's fixed geometry
            self.geom[j.name] = slice(k, k + size)
            k += size
        self.n_shared = k
        # the reference body's pose G[i], unless it is static (held at its start)
        self.pose = slice(0, 0 if static else 6)
        f = self.pose.stop
        self.art = {}
        for j in topo.joints:
            dof = joint_model(j.type).articulation_dof  # its articulation at each frame
            self.art[j.name] = slice(f, f + dof)
            f += dof
        self.block = f
        self.n = n
        self.size = k + f * n

    def frame_columns(self, i: int, sl: slice) -> list[int]:
        start = self.n_shared + self.block * i
        return list(range(start + sl.start, start + sl.stop))


def _apply(R: FloatArray, v: FloatArray) -> FloatArray:
    """``R_i v_i`` for stacks ``(n, 3, 3)`` and ``(n, 3)``."""
    return np.einsum("nij,nj->ni", R, v)


@dataclass
class _Model:
    """The starting point and everything the residuals need besides the unknowns."""

    topo: RigTopology
    L: _Layout
    views: dict[str, CameraViews]
    frames: np.ndarray  # timeline indices adjusted
    rec: np.ndarray  # (n,) the recording of each adjusted frame
    # per recording, the bodies it saw (each with corners or poses at all its frames)
    present: list[frozenset[str]]
    G0: FloatArray  # (n, 4, 4) reference body in the reference world (its virtual pose
    #                 where its recording did not see it)
    W0: dict[tuple[int, str], FloatArray]  # (4, 4) each (recording, body)'s board
    # per joint: its model's fixed rotation (a ball's (n, 3, 3) articulations, a rigid
    # joint's (3, 3)) and starting geometry (JointModel.bundle_start)
    R0: dict[str, FloatArray | None]
    geom0: dict[str, dict[str, FloatArray]]
    obs: dict[str, tuple[np.ndarray, np.ndarray, FloatArray]]  # frame, corner, pixels
    # pose-only bodies: their measured poses (rotations, translations) and the adjusted
    # frames they are at
    meas: dict[str, tuple[FloatArray, FloatArray, np.ndarray]] = field(default_factory=dict)
    # weights (1 / sigma) of the pixel rows and of each pose-only body's rotation and
    # translation rows
    w_px: float = 1.0
    w_rot: dict[str, float] = field(default_factory=dict)
    w_trans: dict[str, float] = field(default_factory=dict)
    # joints known beforehand (edge_prior_rows): (joint, at, value (3,), whitener (k, 3)):
    # rows W (g[at : at + 3] - value) on the joint's geometry (JointModel.bundle_geometry)
    priors: list[tuple[RigJoint, int, FloatArray, FloatArray]] = field(default_factory=list)
    # the articulation unknowns of joints a frame's recording does not see: held at their
    # start by rows of unit weight (they move nothing else, or only what the frame's pose
    # takes back)
    held: np.ndarray = field(default_factory=lambda: np.zeros(0, int))

    @property
    def cams(self) -> list[str]:
        """The bodies with corners, in ``topo.cameras`` order."""
        return [c for c in self.topo.cameras if c in self.views]

    @property
    def bodies(self) -> list[str]:
        """The pose-only bodies, in ``topo.cameras`` order."""
        return [c for c in self.topo.cameras if c in self.meas]

    def intrinsics(self, x: FloatArray, c: str) -> FloatArray:
        out = np.asarray(self.views[c].intrinsics, dtype=float).copy()
        out[self.L.free[c]] = x[self.L.intr[c]]
        return out

    def edge(self, x: FloatArray, j: RigJoint, blocks: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``T_p_q`` of every frame: rotations ``(n, 3, 3)``, translations ``(n, 3)``."""
        e, a = x[self.L.geom[j.name]], blocks[:, self.L.art[j.name]]
        return joint_model(j.type).bundle_edge(e, a, self.R0[j.name], self.geom0[j.name])

    def chain(self, x: FloatArray) -> dict[str, tuple[FloatArray, FloatArray]]:
        """``T_ref_c`` of every camera and frame along the tree."""
        blocks = x[self.L.n_shared :].reshape(self.L.n, self.L.block)
        n = self.L.n
        out: dict[str, tuple[FloatArray, FloatArray]] = {
            self.topo.reference: (np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)))
        }
        for step in self.topo.tree_order():
            R, t = self.edge(x, step.joint, blocks)
            if not step.forward:
                R = np.swapaxes(R, 1, 2)
                t = -_apply(R, t)
            Rs, ts = out[step.source]
            out[step.target] = (np.matmul(Rs, R), ts + _apply(Rs, t))
        return out

    def poses(self, x: FloatArray) -> dict[str, tuple[FloatArray, FloatArray]]:
        """Each camera's pose in the reference board's frame, ``G[i] T_ref_c[i]``."""
        blocks = x[self.L.n_shared :].reshape(self.L.n, self.L.block)
        RG, tG = self.G0[:, :3, :3], self.G0[:, :3, 3]
        if self.L.pose.stop:
            g = blocks[:, self.L.pose]
            RG, tG = np.matmul(RG, se3.matrix_from_rotvec(g[:, :3])), tG + g[:, 3:]
        return {c: (np.matmul(RG, R), tG + _apply(RG, t)) for c, (R, t) in self.chain(x).items()}

    def board(self, x: FloatArray, c: str, r: int = 0) -> tuple[FloatArray, FloatArray]:
        """``W_c``: camera ``c``'s board frame (a pose-only body's world) in recording ``r``
        in the reference world."""
        W0 = self.W0.get((r, c), np.eye(4))
        if (r, c) not in self.L.world:  # a recording's gauge: held
            return W0[:3, :3], W0[:3, 3]
        w = x[self.L.world[(r, c)]]
        return W0[:3, :3] @ se3.matrix_from_rotvec(w[:3]), W0[:3, 3] + w[3:]

    def boards(self, x: FloatArray, c: str) -> tuple[FloatArray, FloatArray]:
        """Body ``c``'s board in every recording, ``(R, 3, 3)`` and ``(R, 3)`` (the
        identity where it was not seen)."""
        Ws = [self.board(x, c, r) for r in range(len(self.present))]
        return np.stack([W[0] for W in Ws]), np.stack([W[1] for W in Ws])

    def raw(self, x: FloatArray) -> tuple[list[FloatArray], dict[str, FloatArray]]:
        """Unweighted residuals: pixels ``(k, 2)`` per camera with corners (in
        :attr:`cams` order, each in its observations' order), and per pose-only body
        ``(n, 6)``: the rotation log ``log(R_M^T R)`` (rad) and the translation difference
        of its predicted pose minus its measured one, in its own world."""
        px_out: list[FloatArray] = []
        poses = self.poses(x)
        for c in self.cams:
            R, t = poses[c]
            fi, ki, px = self.obs[c]
            Rw, tw = self.boards(x, c)
            r = self.rec[fi]
            Xw = _apply(Rw[r], self.views[c].board_points[ki]) + tw[r]
            x_cam = np.einsum("kji,kj->ki", R[fi], Xw - t[fi])  # R^T (W X - t)
            cam = camera_model(self.views[c].model)
            px_out.append(cam.project(x_cam, self.intrinsics(x, c)) - px)
        pose_out: dict[str, FloatArray] = {}
        for b in self.bodies:
            RM, tM, f = self.meas[b]
            R, t = poses[b][0][f], poses[b][1][f]
            Rw, tw = self.boards(x, b)
            Rw, tw = Rw[self.rec[f]], tw[self.rec[f]]
            Rp = np.matmul(np.swapaxes(Rw, 1, 2), R)  # W_b^-1 G_b: its pose in its world
            tp = _apply(np.swapaxes(Rw, 1, 2), t - tw)
            rot = se3.rotvec_from_matrix(np.matmul(np.swapaxes(RM, 1, 2), Rp))
            pose_out[b] = np.concatenate([rot, tp - tM], axis=1)
        return px_out, pose_out

    def residuals(self, x: FloatArray) -> FloatArray:
        """Whitened residuals (the order of :meth:`row_frames`): pixels, then each pose-only
        body's rotation and translation rows frame by frame, the joint priors' rows, and the
        held articulations' rows (:attr:`held`)."""
        px, pose = self.raw(x)
        out = [self.w_px * r.ravel() for r in px]
        for b in self.bodies:
            w = np.array([self.w_rot[b]] * 3 + [self.w_trans[b]] * 3)
            out.append((pose[b] * w).ravel())
        for j, at, value, Wh in self.priors:
            g = joint_model(j.type).bundle_geometry(
                x[self.L.geom[j.name]], self.R0[j.name], self.geom0[j.name]
            )
            out.append(Wh @ (g[at : at + 3] - value))
        out.append(x[self.held])
        return np.concatenate(out)

    def row_frames(self) -> np.ndarray:
        """The frame of each residual row (the order of :meth:`residuals`; a prior's rows,
        which no frame's unknowns touch, are filed under the first frame)."""
        rows = [np.repeat(self.obs[c][0], 2) for c in self.cams]
        rows += [np.repeat(self.meas[b][2], 6) for b in self.bodies]
        rows += [np.zeros(Wh.shape[0], int) for *_, Wh in self.priors]
        rows.append((self.held - self.L.n_shared) // self.L.block)
        return np.concatenate(rows)

    def prior_rows(self) -> np.ndarray:
        """The joint priors' rows in :meth:`residuals` (before the held articulations')."""
        total = self.row_frames().size - self.held.size
        return np.arange(total - sum(Wh.shape[0] for *_, Wh in self.priors), total)

    def pose_rows(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Each pose-only body's rotation and translation rows in :meth:`residuals`."""
        start = sum(2 * self.obs[c][0].size for c in self.cams)
        out = {}
        for b in self.bodies:
            m = self.meas[b][2].size
            rows = start + np.arange(6 * m).reshape(m, 6)
            out[b] = (rows[:, :3].ravel(), rows[:, 3:].ravel())
            start += 6 * m
        return out


def _check(
    topo: RigTopology,
    views: dict[str, CameraViews],
    poses: dict[str, CameraTrack],
    est: RigEstimate,
    static: bool = False,
) -> int:
    """The timeline's length; ``InputError`` naming what does not fit."""
    missing = [
        c
        for c in topo.cameras
        if c not in views and c not in poses and not (static and c == topo.reference)
    ]
    if missing:
        raise InputError(
            f"no corners for camera(s) {', '.join(missing)}, and no poses to fit as bodies "
            "without corners"
        )
    both = [c for c in topo.cameras if c in views and c in poses]
    if both:
        raise InputError(
            f"camera(s) {', '.join(both)} given corners and poses: a body of the bundle has "
            "one or the other"
        )
    if not any(c in views for c in topo.cameras):
        raise InputError("no camera of the rig has corners: a bundle adjustment needs one")
    n = est.cameras[topo.reference].poses_in_reference_world.shape[0]
    for c, v in views.items():
        if v.corners.ndim != 3 or v.corners.shape[2] != 2:
            raise InputError(
                f"camera {c}: corners must have shape (n, m, 2), got {v.corners.shape}"
            )
        if v.valid.shape != v.corners.shape[:2]:
            raise InputError(f"camera {c}: valid must have shape {v.corners.shape[:2]}")
        if v.board_points.shape != (v.corners.shape[1], 3):
            raise InputError(f"camera {c}: board points must have shape ({v.corners.shape[1]}, 3)")
        size = camera_model(v.model).size
        if np.asarray(v.intrinsics).shape != (size,):
            raise InputError(f"camera {c}: its {v.model} model's intrinsics have shape ({size},)")
        if v.corners.shape[0] != n:
            raise InputError(f"camera {c}: {v.corners.shape[0]} instants, the rig estimate {n}")
    for c, tr in poses.items():
        if c not in topo.cameras:
            raise InputError(f"poses given for {c}, which is not in the rig")
        if tr.T_w_c.shape != (n, 4, 4) or tr.valid.shape != (n,):
            raise InputError(f"body {c}: its poses are not on the rig's timeline of {n} instants")
        se3.check_transforms(tr.T_w_c[tr.valid], name=f"body {c}'s poses")
    return n


def _in_reference_world(est: RigEstimate) -> set[str]:
    """The bodies in the reference camera's world at the reference instant: itself, or
    every body of its recording when they share one world (``world: shared``): their board
    is the reference's, with no unknowns of its own."""
    ref = est.topology.reference
    recs = est.recordings
    if recs is None:
        return {ref}
    here = recs.names[int(recs.of_frame[est.reference_frame])]
    for w in est.worlds:
        if w.recording == here and w.shared and ref in w.cameras:
            return set(w.cameras)
    return {ref}


def _recordings(
    topo: RigTopology, est: RigEstimate, frames: np.ndarray
) -> tuple[np.ndarray, list[frozenset[str]]]:
    """The recording of each adjusted frame ``(n,)`` and, per recording, the bodies it names
    (its worlds' bodies; every body in a one-recording estimate; none in a recording without
    frames adjusted, e.g. one that holds a joint still: nothing there has unknowns, and its
    poses stay mapped by the pose-based estimate's worlds); ``InputError`` for a recording
    whose bodies the rig's tree does not join through bodies it saw (each would need a pose
    of its own, which the bundle does not carry)."""
    recs = est.recordings
    if recs is None or not est.worlds:
        return np.zeros(frames.size, int), [frozenset(topo.cameras)] * (
            1 if recs is None else len(recs.names)
        )
    present: list[frozenset[str]] = []
    parent = {s.target: s.source for s in topo.tree_order()}
    adjusted = set(recs.of_frame[frames].tolist())
    for r, name in enumerate(recs.names):
        if r not in adjusted:
            present.append(frozenset())
            continue
        here = frozenset(c for w in est.worlds if w.recording == name for c in w.cameras)
        roots = [c for c in here if parent.get(c) not in here]
        if len(roots) > 1:
            raise InputError(
                f"recordings.{name}: bodies {', '.join(sorted(roots))} are not joined by "
                "joints between bodies it saw; the bundle adjustment takes recordings whose "
                "bodies form one connected part of the rig"
            )
        present.append(here)
    return recs.of_frame[frames], present


def _world_starts(
    est: RigEstimate, present: list[frozenset[str]]
) -> dict[tuple[int, str], FloatArray]:
    """Each (recording, body)'s board in the reference world, from the pose-based
    estimate's worlds (a one-world estimate: each body's ``world_to_reference_world``)."""
    out: dict[tuple[int, str], FloatArray] = {}
    recs = est.recordings
    for r, here in enumerate(present):
        for c in here:
            out[(r, c)] = est.cameras[c].world_to_reference_world
            for w in est.worlds:
                if recs is not None and w.recording == recs.names[r] and c in w.cameras:
                    out[(r, c)] = w.T_ref_world
    return out


def _initial(
    topo: RigTopology,
    views: dict[str, CameraViews],
    poses: dict[str, CameraTrack],
    est: RigEstimate,
    frames: np.ndarray,
    rec: np.ndarray,
    present: list[frozenset[str]],
    hold_intrinsics: bool,
    static: bool = False,
) -> tuple[_Model, FloatArray]:
    """The model and its starting unknowns, from the pose-based estimate (every camera's
    intrinsics held, or its model's default free ones refined; a static reference body: the
    world of a joint held still, whose bodies' boards are that world).

    Each recording's boards are fixed up to one rigid motion with its frames' poses: the
    gauge holds the reference's world (and the bodies sharing it) in its recording, and in
    every other recording the board of its body nearest the reference in the tree (all of
    them in a shared world). ``rec`` and ``present``: :func:`_recordings`."""
    k = int(np.flatnonzero(frames == est.reference_frame)[0])
    order = [topo.reference] + [s.target for s in topo.tree_order()]
    shared = () if est.recordings is None else est.recordings.shared_world
    gauge: list[set[str]] = []
    for r, here in enumerate(present):
        if static:
            gauge.append(set(topo.cameras))
        elif r == rec[k]:
            gauge.append(_in_reference_world(est))
        elif r < len(shared) and shared[r]:
            gauge.append(set(here))
        else:
            gauge.append({next(c for c in order if c in here)} if here else set())
    L = _Layout(
        topo,
        frames.size,
        {c: [] if hold_intrinsics else camera_model(v.model).free() for c, v in views.items()},
        [(r, c) for r, here in enumerate(present) for c in topo.cameras if c in here - gauge[r]],
        static,
    )
    G = {c: est.cameras[c].poses_in_reference_world[frames] for c in topo.cameras}
    x = np.zeros(L.size)
    blocks = np.zeros((frames.size, L.block))
    R0: dict[str, FloatArray | None] = {}
    geom0: dict[str, dict[str, FloatArray]] = {}
    held: list[int] = []
    for j in topo.joints:
        p, q = j.between
        e = est.edges[j.name]
        active = np.array([p in present[r] and q in present[r] for r in rec])
        T_p_q = np.matmul(se3.invert_transforms(G[p]), G[q])
        T_p_q[~active] = np.eye(4)
        R0[j.name], geom0[j.name], x[L.geom[j.name]], blocks[:, L.art[j.name]] = joint_model(
            j.type
        ).bundle_start(
            [e.position_in[c] for c in (p, q) if c in e.position_in],
            e.axis_in.get(p),
            e.T_q_p,
            T_p_q,
            k if active[k] else int(np.argmax(active)),
        )
        blocks[~active, L.art[j.name]] = 0.0
        held += [c for i in np.flatnonzero(~active) for c in L.frame_columns(int(i), L.art[j.name])]
    intr = np.zeros(L.n_shared)
    for c in views:
        intr[L.intr[c]] = np.asarray(views[c].intrinsics, float)[L.free[c]]
    x[: L.n_shared] += intr
    x[L.n_shared :] = blocks.ravel()
    obs = {}
    for c, v in views.items():
        fi, ki = np.nonzero(observed(v.corners, v.valid, v.board_points)[frames])
        obs[c] = (fi, ki, v.corners[frames][fi, ki])
    meas = {}
    for b, tr in poses.items():
        f = np.flatnonzero(tr.valid[frames])
        meas[b] = (tr.T_w_c[frames[f], :3, :3].copy(), tr.T_w_c[frames[f], :3, 3].copy(), f)
    model = _Model(
        topo=topo,
        L=L,
        views=views,
        frames=frames,
        rec=rec,
        present=present,
        G0=G[topo.reference].copy(),
        W0=_world_starts(est, present),
        R0=R0,
        geom0=geom0,
        obs=obs,
        meas=meas,
        held=np.asarray(held, dtype=int),
    )
    # where a recording did not see the reference body, its pose is virtual: the one that
    # puts the recording's first body (nearest the reference) where the estimate has it
    chain = model.chain(x)
    for r, here in enumerate(present):
        f = np.flatnonzero(rec == r)
        if topo.reference in here or not here or not f.size:
            continue
        root = next(c for c in order if c in here)
        R, t = chain[root]
        T_ref_root = se3.transforms_from_rt(R[f], t[f])
        model.G0[f] = np.matmul(G[root][f], se3.invert_transforms(T_ref_root))
    return model, x


def bundle_adjust_rig(
    topology: RigTopology,
    views: dict[str, CameraViews],
    initial: RigEstimate,
    frames: np.ndarray,
    poses: dict[str, CameraTrack] | None = None,
    priors: dict[str, EdgePrior] | None = None,
    static: bool = False,
    hold_intrinsics: bool | None = None,
) -> RigBundle:
    """Maximum-likelihood calibration of a rig from its cameras' board corners and the
    measured poses of its pose-only bodies (and joints known beforehand).

    Parameters
    ----------
    topology : RigTopology
    views : dict of CameraViews
        The corners on the rig's timeline (metric boards) of every body that has them (at
        least one).
    initial : RigEstimate
        The pose-based estimate (:func:`acs_cli.core.rig_solve.estimate_rig`) on the same
        timeline, metric (every camera of known scale).
    frames : ndarray of int
        The instants to adjust (every body of the instant's recording sees its board
        there, or has a pose); they must include the reference instant.
    poses : dict of CameraTrack, optional
        The measured poses (``T_world_body`` in the body's own world, metres) of every
        body without corners (a robot's flange, a motion-capture segment, an INS).
    priors : dict of EdgePrior, optional
        Joints known beforehand (a fixed-joint session, a measurement), by joint name: their
        points (``position_in``, metres, with ``covariance_in``; without one, the pose-based
        solve's default std), a hinge's lines and axes (``line_in``, ``axis_in``), fused
        with the corners as in the pose-based solve (:func:`acs_cli.core.rig_solve.estimate_rig`).
    static : bool
        The reference body does not move: it is the world of a joint held still (the
        paper's fixed-joint motion, a pivot; :func:`bundle_adjust_fixed_joint`), with
        neither corners nor poses, its pose held at ``initial``'s, and every other body's
        board in it.
    hold_intrinsics : bool, optional
        Hold every camera's intrinsics (the rig's geometry, boards and poses fitted on the
        corners: OpenCV's ``stereoCalibrate`` with ``CALIB_FIX_INTRINSIC``) or refine them;
        by default refined on at least :data:`MIN_INTRINSICS_FRAMES` frames when the corners
        determine them, held otherwise (``RigBundle.intrinsics_held`` says why).

    Returns
    -------
    RigBundle

    Raises
    ------
    InputError
        Views or poses that do not fit the topology or the timeline, a body with neither,
        an unknown scale, frames without the reference instant, or a prior that does not
        fit its joint.
    DegenerateMotionError
        Corners and poses that leave part of the rig undetermined (too few frames, or
        motion that does not show a joint: a rigid pair in one world needs 1 frame, a
        hinge 2, a ball 3; separate worlds more).
    """
    poses = dict(poses or {})
    n_total = _check(topology, views, poses, initial, static)
    frames = np.unique(np.asarray(frames, dtype=int))
    if frames[0] < 0 or frames[-1] >= n_total or initial.reference_frame not in frames:
        raise InputError("the frames must be on the timeline and include the reference instant")
    for c, v in views.items():  # (the messages name the board's corners)
        observed(v.corners, v.valid, v.board_points, f"camera {c}'s corners")
    rec, present = _recordings(topology, initial, frames)
    for c, v in views.items():
        f = frames[[c in present[r] for r in rec]]
        check_frame_corners(observed(v.corners, v.valid, v.board_points)[f], f"camera {c}", f)
    for b, tr in poses.items():
        f = frames[[b in present[r] for r in rec]]
        gaps = f[~tr.valid[f]]
        if gaps.size:
            raise InputError(
                f"body {b} has no pose at frame(s) {', '.join(map(str, gaps[:5]))}: a bundle "
                "adjustment takes frames where every body has its measurement"
            )
    unknown = [c for c, e in initial.cameras.items() if e.scale_std is not None]
    if unknown:
        raise InputError(
            f"camera(s) {', '.join(unknown)} have an unknown scale; corners are metric"
        )
    args = (topology, views, poses, initial, frames, priors, rec, present, static)
    if hold_intrinsics is not None:
        return _adjust(*args, hold_intrinsics)
    why: str | None = f"{frames.size} frames, fewer than a camera's calibration needs"
    if frames.size >= MIN_INTRINSICS_FRAMES:
        try:
            ba = _adjust(*args, False)
            why = _undetermined(views, ba)
        except DegenerateMotionError:  # the rig itself may be undetermined: held, again
            why = "the corners do not determine them"
        if why is None:
            return ba
    return dataclasses.replace(_adjust(*args, True), intrinsics_held=why)


def _undetermined(views: dict[str, CameraViews], ba: RigBundle) -> str | None:
    """Why the corners do not determine the intrinsics refined by ``ba``: the first camera
    whose refined distortion is degenerate
    (:func:`acs_cli.core.intrinsics.degenerate_distortion`), or None."""
    for c, v in views.items():
        p = ba.intrinsics_covariance[c]
        found = degenerate_distortion(v.model, ba.intrinsics[c][4:], p[4:, 4:])
        if found:
            return f"camera {c}: {found}"
    return None


def _adjust(
    topology: RigTopology,
    views: dict[str, CameraViews],
    poses: dict[str, CameraTrack],
    initial: RigEstimate,
    frames: np.ndarray,
    priors: dict[str, EdgePrior] | None,
    rec: np.ndarray,
    present: list[frozenset[str]],
    static: bool,
    hold: bool,
) -> RigBundle:
    """:func:`bundle_adjust_rig` on checked input, every camera's intrinsics ``hold`` or
    refined."""
    model, x0 = _initial(topology, views, poses, initial, frames, rec, present, hold, static)
    k_ref = int(np.flatnonzero(frames == initial.reference_frame)[0])
    model.priors = _bundle_priors(model, priors or {}, k_ref)
    L = model.L
    row_frame = model.row_frames()

    last: dict[bytes, FloatArray] = {}

    def fun(x: FloatArray) -> FloatArray:
        """The residuals, remembered at the last point (the solver asks for the Jacobian
        where it has just evaluated them, and the differences start from them)."""
        key = x.tobytes()
        if key not in last:
            last.clear()
            last[key] = model.residuals(x)
        return last[key]

    def jac(x: FloatArray) -> object:
        return lsq.block_jacobian(model.residuals, x, fun(x), L.n_shared, L.block, row_frame)

    if model.bodies or model.priors:  # weights of known and fitted noise levels together
        _start_noise(model, x0)
    _factor(jac(x0), UNDETERMINED_SHARE)  # the frames determine every unknown, or refused
    if model.bodies or model.priors:
        x = x0
        # the refits are a fixed-point iteration s -> F(s) on the log noise levels, which
        # converges slowly where a body's pose noise and the corners' depth noise trade
        # off: Anderson's acceleration over the last few iterates
        s_in: list[FloatArray] = []
        s_out: list[FloatArray] = []
        for _ in range(NOISE_ROUNDS):
            s_in.append(_noise(model))
            sol = lsq.solve(fun, x, jac=jac, method="normal", xtol=1e-11)
            x = sol.x
            _refit_noise(model, sol.x, sol.jac)
            last.clear()  # the weights changed
            s_out.append(_noise(model))
            if np.max(np.abs(s_out[-1] - s_in[-1])) <= NOISE_SETTLED:
                break
            _set_noise(model, _anderson(s_in[-4:], s_out[-4:]))
        # at the settled weights; a second solve from there takes the Gauss-Newton steps
        # the first one's relative-cost test stops short of along weakly determined
        # directions (where the cost is flat), so that the solution is the same whichever
        # way the rig is written down
        for _ in range(2):
            sol = lsq.solve(fun, x, jac=jac, method="normal")
            x = sol.x
        sigma2 = 1.0 / model.w_px**2
        scale = 1.0  # the whitened residuals have unit variance at the fitted levels
    else:
        sol = lsq.solve(fun, x0, jac=jac, method="normal")
        dof = max(sol.fun.size - x0.size, 1)
        sigma2 = float(sol.fun @ sol.fun / dof)
        scale = sigma2
    x = sol.x
    cols = list(range(L.n_shared)) + L.frame_columns(k_ref, slice(0, L.block))
    cov = scale * _inverse_columns(sol.jac, cols)
    cov, found = _correlated(model, sol.jac, sol.fun / scale, row_frame, cov)
    where = {c: i for i, c in enumerate(cols)}
    est = _assemble(model, x, cov, where, k_ref, initial)
    est = dataclasses.replace(est, correlated=found)
    intr = {c: model.intrinsics(x, c) for c in model.cams}
    std: dict[str, FloatArray] = {}
    icov: dict[str, FloatArray] = {}
    for c in model.cams:
        ci = np.zeros((intr[c].size, intr[c].size))
        idx = [where[i] for i in range(L.intr[c].start, L.intr[c].stop)]
        ci[np.ix_(L.free[c], L.free[c])] = cov[np.ix_(idx, idx)]
        icov[c] = ci
        std[c] = np.sqrt(np.maximum(np.diag(ci), 0.0))
    px, pose = model.raw(x)
    rms = {
        c: float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) if r.size else 0.0
        for c, r in zip(model.cams, px, strict=True)
    }
    per_frame = {}
    for c, r in zip(model.cams, px, strict=True):
        fi = model.obs[c][0]
        counts = np.maximum(np.bincount(fi, minlength=frames.size), 1)
        per_frame[c] = np.sqrt(
            np.bincount(fi, weights=np.sum(r**2, axis=1), minlength=frames.size) / counts
        )
    bodies = _pose_bodies(model, x, cov, where, pose)
    cams = dict(est.cameras)
    for b, fit in bodies.items():
        e = cams[b]
        fields = {f.name: getattr(e, f.name) for f in dataclasses.fields(e)}
        cams[b] = PoseBodyEstimate(**fields, pose_fit=fit)
    est = dataclasses.replace(est, cameras=cams)
    return RigBundle(
        est, intr, std, icov, rms, float(np.sqrt(sigma2)), frames, bool(sol.success), bodies,
        per_frame, "held as asked" if hold else None,
    )  # fmt: skip


def _correlated(
    model: _Model, J: object, r: FloatArray, row_frame: np.ndarray, cov: FloatArray
) -> tuple[FloatArray, CorrelatedErrors]:
    """``cov`` (the shared unknowns first) grown for errors correlated over time
    (:mod:`acs_cli.core.correlated`): per adjusted frame, the scores ``J^T r`` of its corner
    and pose rows for the shared unknowns (``r`` the residuals over their variance),
    tested per camera's intrinsics, per board and per joint's geometry."""
    L = model.L
    n_rows = sum(2 * model.obs[c][0].size for c in model.cams)
    n_rows += sum(6 * model.meas[b][2].size for b in model.bodies)
    shared = list(range(L.n_shared))
    rows = scipy.sparse.csr_matrix(J)[:n_rows]
    scores = frame_scores(rows, r[:n_rows], row_frame[:n_rows], shared)
    groups: dict[str, list[int]] = {}
    for c, sl in L.intr.items():
        groups[f"intrinsics of {c}"] = list(range(sl.start, sl.stop))
    for (rec, body), sl in L.world.items():
        groups[f"the board of {body} (recording {rec})"] = list(range(sl.start, sl.stop))
    for name, sl in L.geom.items():
        groups[f"joint {name}"] = list(range(sl.start, sl.stop))
    return covariance_with_correlated_errors(cov, scores, shared, groups)


def _bundle_priors(
    model: _Model, priors: dict[str, EdgePrior], k: int
) -> list[tuple[RigJoint, int, FloatArray, FloatArray]]:
    """The rows of joints known beforehand, as the pose-based solve takes them
    (:func:`~acs_cli.core.rig_solve.edge_prior_rows`: points, a hinge's lines and axes, in
    metres: every body of the bundle is metric); a point without a covariance has the
    engine's default std, its share of the reference body's travel over the frames adjusted
    in the reference instant's (``k``) recording (the others' are placed in the reference
    world by a choice of gauge, or are virtual poses)."""
    t = model.G0[model.rec == model.rec[k], :3, 3]
    travel = float(np.sqrt(np.mean(np.sum((t - t.mean(axis=0)) ** 2, axis=1))))
    return [
        (model.topo.joint(name), at, value, W)
        for name, at, value, W, _c in edge_prior_rows(model.topo, priors, travel)
    ]


def _noise(model: _Model) -> FloatArray:
    """The current noise levels: logs of the pixel sigma and each pose-only body's."""
    out = [model.w_px]
    for b in model.bodies:
        out += [model.w_rot[b], model.w_trans[b]]
    return -np.log(np.asarray(out))


def _set_noise(model: _Model, s: FloatArray) -> None:
    """Set the weights from log noise levels ``s`` (the order of :func:`_noise`)."""
    w = np.exp(-np.asarray(s))
    model.w_px = float(w[0])
    for i, b in enumerate(model.bodies):
        model.w_rot[b], model.w_trans[b] = float(w[1 + 2 * i]), float(w[2 + 2 * i])


def _anderson(s_in: list[FloatArray], s_out: list[FloatArray]) -> FloatArray:
    """The next iterate of a fixed-point iteration ``s_out[k] = F(s_in[k])`` by Anderson's
    acceleration over the iterates given (the plain ``F`` when it would move more than a
    factor of 4 past it, or with one iterate)."""
    last = s_out[-1]
    if len(s_in) < 2:
        return last
    f = [o - i for i, o in zip(s_in, s_out, strict=True)]
    dF = np.stack([f[k + 1] - f[k] for k in range(len(f) - 1)], axis=1)
    dG = np.stack([s_out[k + 1] - s_out[k] for k in range(len(f) - 1)], axis=1)
    gamma = np.linalg.lstsq(dF, f[-1], rcond=1e-10)[0]
    out = last - dG @ gamma
    return np.asarray(out if np.max(np.abs(out - last)) < np.log(4.0) else last)


def _floors(model: _Model, b: str) -> tuple[float, float]:
    """The lowest rotation (rad) and translation (m) sigma of body ``b``'s poses."""
    t = model.meas[b][1]
    travel = float(np.sqrt(np.mean(np.sum((t - t.mean(axis=0)) ** 2, axis=1))))
    return NOISE_FLOOR_ROT, NOISE_FLOOR_LENGTH * max(travel, 1e-3)


def _start_noise(model: _Model, x: FloatArray) -> None:
    """Starting weights: each group's RMS per coordinate at the starting point."""
    px, pose = model.raw(x)
    allpx = np.concatenate([r.ravel() for r in px])
    model.w_px = 1.0 / max(float(np.sqrt(np.mean(allpx**2))), 1e-3)
    for b in model.bodies:
        fr, ft = _floors(model, b)
        model.w_rot[b] = 1.0 / max(float(np.sqrt(np.mean(pose[b][:, :3] ** 2))), fr)
        model.w_trans[b] = 1.0 / max(float(np.sqrt(np.mean(pose[b][:, 3:] ** 2))), ft)


def _refit_noise(model: _Model, x: FloatArray, J: object) -> None:
    """One variance-component refit (Förstner): each group's squared residuals over its
    redundancy ``n_k - tr(H^-1 J_k^T J_k)`` (``H`` the whitened information); the pixel
    rows take what the pose rows leave of the unknowns (the traces add up to their number)."""
    cf, d = _factor(J)
    Js = scipy.sparse.csr_array(J) @ scipy.sparse.diags_array(d)
    px, pose = model.raw(x)
    taken = 0.0
    for b, (rot_rows, trans_rows) in model.pose_rows().items():
        fr, ft = _floors(model, b)
        for rows, e, floor, key in (
            (rot_rows, pose[b][:, :3], fr, "rot"),
            (trans_rows, pose[b][:, 3:], ft, "trans"),
        ):
            Jk = np.asarray(Js[rows].toarray())
            a = float(np.sum(Jk.T * scipy.linalg.cho_solve(cf, Jk.T)))
            taken += a
            var = float(np.sum(e**2)) / max(rows.size - a, 1.0)
            w = 1.0 / max(np.sqrt(var), floor)
            if key == "rot":
                model.w_rot[b] = w
            else:
                model.w_trans[b] = w
    if model.priors:  # their rows take their share of the unknowns too (known weights)
        Jk = np.asarray(Js[model.prior_rows()].toarray())
        taken += float(np.sum(Jk.T * scipy.linalg.cho_solve(cf, Jk.T)))
    taken += model.held.size  # each held unknown's row takes it whole
    allpx = np.concatenate([r.ravel() for r in px])
    redundancy = max(allpx.size - (x.size - taken), 1.0)
    model.w_px = 1.0 / max(float(np.sqrt(np.sum(allpx**2) / redundancy)), 1e-6)


def _pose_bodies(
    model: _Model,
    x: FloatArray,
    cov: FloatArray,
    where: dict[int, int],
    pose: dict[str, FloatArray],
) -> dict[str, PoseBodyFit]:
    """Each pose-only body's noise, residuals and every corner camera's board in its world."""
    L = model.L
    out = {}
    for b in model.bodies:
        boards: dict[str, FloatArray] = {}
        covs: dict[str, FloatArray] = {}
        for c in model.cams:
            both = [r for r, here in enumerate(model.present) if {b, c} <= here]
            if not both:  # never seen together: no board in the body's world
                continue
            r = both[0]

            def T(xx: FloatArray, c: str = c, b: str = b, r: int = r) -> FloatArray:
                Rb, tb = model.board(xx, b, r)
                Rc, tc = model.board(xx, c, r)
                return se3.transforms_from_rt(Rb.T @ Rc, Rb.T @ (tc - tb))

            T0 = T(x)

            def vec(xx: FloatArray, T: object = T, T0: FloatArray = T0) -> FloatArray:
                Tx = T(xx)  # type: ignore[operator]
                return np.concatenate(
                    [se3.rotvec_from_matrix(T0[:3, :3].T @ Tx[:3, :3]), Tx[:3, 3]]
                )

            cols = [
                i
                for w in ((r, b), (r, c))
                if w in L.world
                for i in range(L.world[w].start, L.world[w].stop)
            ]
            idx = [where[i] for i in cols]
            boards[c] = T0
            covs[c] = lsq.propagate(vec, x, cols, cov[np.ix_(idx, idx)])[1]
        e = pose[b]
        out[b] = PoseBodyFit(
            frames=int(model.meas[b][2].size),
            sigma_rot_deg=float(np.degrees(1.0 / model.w_rot[b])),
            sigma_trans=float(1.0 / model.w_trans[b]),
            rms_rot_deg=float(np.degrees(np.sqrt(np.mean(np.sum(e[:, :3] ** 2, axis=1))))),
            rms_trans=float(np.sqrt(np.mean(np.sum(e[:, 3:] ** 2, axis=1)))),
            T_world_board=boards,
            T_world_board_covariance=covs,
        )
    return out


def _relative(
    T_q_ref: FloatArray | None, T_p_ref: FloatArray | None, otherwise: FloatArray
) -> FloatArray:
    """``T_q_p`` from two ``T_cam_ref``; ``otherwise`` when either camera has none (a joint
    of a recording without the reference instant)."""
    if T_q_ref is None or T_p_ref is None:
        return otherwise
    return T_q_ref @ se3.invert_transforms(T_p_ref)


def _factor(J: object, share: float = 0.0) -> tuple[tuple[FloatArray, bool], FloatArray]:
    """The Cholesky factor of the information ``J^T J`` scaled to a unit diagonal (far better
    conditioned), and the scales ``d`` ``(p,)`` (``H = D^-1 F D^-1``, ``D = diag(d)``).

    Raises
    ------
    DegenerateMotionError
        When the information is singular: not positive definite, or an unknown with at most
        ``share`` of its information not explained by the unknowns before it (a joint, a
        board or a body's world the frames do not determine).
    """
    H = information(J)
    d = 1.0 / np.sqrt(np.maximum(np.diag(H), 1e-300))
    try:
        cf = scipy.linalg.cho_factor(H * np.outer(d, d))
        least = float(np.min(np.diag(cf[0]))) ** 2
    except np.linalg.LinAlgError:
        least = 0.0
    if not least > share:
        raise DegenerateMotionError(
            "the corners and poses do not determine the rig (its information matrix is "
            "singular: a joint, a board or a body's world that the frames cannot see)",
        )
    return cf, d


def _inverse_columns(J: object, cols: list[int]) -> FloatArray:
    """``(J^T J)^-1`` restricted to ``cols`` (rows and columns), by a Cholesky solve of the
    column-scaled information for those columns only; ``DegenerateMotionError`` when the
    information is singular."""
    cf, d = _factor(J)
    E = np.zeros((d.size, len(cols)))
    E[cols, np.arange(len(cols))] = d[cols]
    return np.asarray((d[:, None] * scipy.linalg.cho_solve(cf, E))[cols])


def _assemble(
    model: _Model,
    x: FloatArray,
    cov: FloatArray,
    where: dict[int, int],
    k_ref: int,
    initial: RigEstimate,
) -> RigEstimate:
    """The rig estimate at the bundle's solution, with covariances from ``cov`` (over the
    columns ``where`` maps)."""
    topo, L = model.topo, model.L

    def sub(cols: list[int]) -> FloatArray:
        idx = [where[c] for c in cols]
        return cov[np.ix_(idx, idx)]

    def T_cam_ref(xx: FloatArray, c: str) -> FloatArray:
        R, t = model.chain(xx)[c]
        return se3.invert_transforms(se3.transforms_from_rt(R[k_ref], t[k_ref]))

    poses = model.poses(x)
    r_ref = int(model.rec[k_ref])
    recs = initial.recordings
    n_all = initial.cameras[topo.reference].poses_in_reference_world.shape[0]
    of_frame = np.zeros(n_all, int) if recs is None else recs.of_frame
    cams: dict[str, CameraEstimate] = {}
    for c in topo.cameras:
        c0 = initial.cameras[c]
        # every measured pose mapped into the reference world by its recording's refined
        # board frame (as the pose-based solve maps them by its own)
        Rw, tw = model.boards(x, c)
        W0 = np.stack([model.W0.get((r, c), np.eye(4)) for r in range(len(model.present))])
        D = np.matmul(se3.transforms_from_rt(Rw, tw), se3.invert_transforms(W0))
        world = np.matmul(D[of_frame], c0.poses_in_reference_world)
        # at the instants adjusted where its recording saw it, the bundle's own poses
        # G[i] T_ref_c[i] (the reference instant's is the one T_cam_ref describes)
        seen = np.array([c in model.present[r] for r in model.rec], dtype=bool)
        R_c, t_c = poses[c]
        world[model.frames[seen]] = se3.transforms_from_rt(R_c[seen], t_c[seen])
        if c0.T_cam_ref is None or c not in model.present[r_ref]:  # not at the reference
            cams[c] = dataclasses.replace(c0, poses_in_reference_world=world)
            continue
        T0 = T_cam_ref(x, c)
        cols: list[int] = []
        for s in topo.path(topo.reference, c):
            cols += list(range(L.n_shared))[L.geom[s.joint.name]]
            cols += L.frame_columns(k_ref, L.art[s.joint.name])

        def vec(xx: FloatArray, c: str = c, T0: FloatArray = T0) -> FloatArray:
            T = T_cam_ref(xx, c)
            return np.concatenate([se3.rotvec_from_matrix(T0[:3, :3].T @ T[:3, :3]), T[:3, 3]])

        C6 = lsq.propagate(vec, x, cols, sub(cols))[1] if cols else np.zeros((6, 6))
        W = se3.transforms_from_rt(Rw[r_ref], tw[r_ref])
        cams[c] = dataclasses.replace(
            c0,
            T_cam_ref=T0,
            covariance=C6,
            poses_in_reference_world=world,
            world_to_reference_world=W,
        )
    edges: dict[str, EdgeEstimate] = {}
    for j in topo.joints:
        p, q = j.between
        e0 = initial.edges[j.name]
        cols = list(range(L.n_shared))[L.geom[j.name]]
        T_q_p = _relative(cams[q].T_cam_ref, cams[p].T_cam_ref, e0.T_q_p)
        jm = joint_model(j.type)
        if jm.constant_transform:

            def T_q_p_of(xx: FloatArray, j: RigJoint = j, jm: JointModel = jm) -> FloatArray:
                R, t = jm.bundle_edge(
                    xx[L.geom[j.name]], np.zeros((1, 0)), model.R0[j.name], model.geom0[j.name]
                )
                return se3.transforms_from_rt(R[0].T, -R[0].T @ t[0])

            T_rig = T_q_p_of(x)

            def rel(xx: FloatArray, T0: FloatArray = T_rig, f: object = T_q_p_of) -> FloatArray:
                T = f(xx)  # type: ignore[operator]
                return np.concatenate([se3.rotvec_from_matrix(T0[:3, :3].T @ T[:3, :3]), T[:3, 3]])

            C = lsq.propagate(rel, x, cols, sub(cols))[1]
            edges[j.name] = RigidEdgeEstimate(
                **{f.name: getattr(e0, f.name) for f in dataclasses.fields(e0)}
                | {"T_q_p": T_rig, "T_q_p_covariance": C}
            )
            continue

        def geometry(xx: FloatArray, j: RigJoint = j, jm: JointModel = jm) -> FloatArray:
            return jm.bundle_geometry(xx[L.geom[j.name]], model.R0[j.name], model.geom0[j.name])

        g, Cg = lsq.propagate(geometry, x, cols, sub(cols))
        pos = {p: g[:3], q: g[3:6]}
        pcov = {p: Cg[:3, :3], q: Cg[3:6, 3:6]}
        axis: dict[str, FloatArray] = {}
        astd: dict[str, float] = {}
        if jm.has_axis:
            # one convention for the axis's sign (as the pose-based solve): its largest
            # component in p is positive
            sign = 1.0 if g[6 + int(np.argmax(np.abs(g[6:9])))] >= 0 else -1.0
            axis = {p: sign * g[6:9], q: sign * g[9:12]}
            astd = {
                p: float(np.degrees(np.sqrt(max(np.trace(Cg[6:9, 6:9]), 0.0)))),
                q: float(np.degrees(np.sqrt(max(np.trace(Cg[9:12, 9:12]), 0.0)))),
            }
        edges[j.name] = dataclasses.replace(
            e0,
            position_in=pos,
            position_cov_in=pcov,
            axis_in=axis,
            axis_std_deg_in=astd,
            T_q_p=T_q_p,
            position_own_in={c: (pos[c], pcov[c]) for c in (p, q)},
            geometry=g,
            geometry_covariance=Cg,
        )  # fmt: skip  (a metric rig: each camera's own units are the reference's)
    worlds = []
    names = () if recs is None else recs.names
    for w in initial.worlds:  # each world with unknowns: the bundle's, with its covariance
        r = names.index(w.recording) if w.recording in names else -1
        sl = model.L.world.get((r, w.cameras[0]))
        if sl is not None and not w.shared:
            Rw, tw = model.board(x, w.cameras[0], r)
            w = dataclasses.replace(
                w,
                T_ref_world=se3.transforms_from_rt(Rw, tw),
                covariance=sub(list(range(sl.start, sl.stop))),
            )
        worlds.append(w)
    return dataclasses.replace(
        initial, cameras=cams, edges=edges, worlds=worlds, bundle_frames=model.frames
    )


@dataclass(frozen=True)
class FixedJointBundle:
    """Result of :func:`bundle_adjust_fixed_joint`.

    Attributes
    ----------
    model : str
        The camera model (:data:`acs_cli.core.camera_models.CAMERA_MODELS`).
    intrinsics : ndarray, shape (p,)
        Named by the model's ``names`` (``fx fy cx cy k1 k2 p1 p2 k3`` for pinhole).
    intrinsics_covariance : ndarray, shape (p, p)
        Pixel noise estimated; 0 rows and columns for held intrinsics.
    joint_in_cam : ndarray, shape (3,)
        The joint in the camera's frame (metres, the board's unit).
    joint_covariance : ndarray, shape (3, 3)
        Of ``joint_in_cam`` (metres squared).
    joint_in_world : ndarray, shape (3,)
        The joint in the board's frame.
    rms_px : float
        Reprojection RMS over the corners used.
    per_frame_rms_px : ndarray, shape (n,)
    sigma_px : float
        Estimated standard deviation of a corner coordinate.
    success : bool
    """

    model: str
    intrinsics: FloatArray
    intrinsics_covariance: FloatArray
    joint_in_cam: FloatArray
    joint_covariance: FloatArray
    joint_in_world: FloatArray
    rms_px: float
    per_frame_rms_px: FloatArray
    sigma_px: float
    success: bool
    #: the test for errors correlated over time (the covariances include what it found)
    correlated: CorrelatedErrors = NOT_TESTED

    @property
    def intrinsics_std(self) -> FloatArray:
        """``(p,)`` standard deviations of the intrinsics (0 for held ones)."""
        return np.sqrt(np.clip(np.diag(self.intrinsics_covariance), 0.0, None))

    @property
    def joint_std(self) -> FloatArray:
        return np.sqrt(np.diag(self.joint_covariance))


#: A fixed-joint session as a rig: its world (the board) and the camera, joined by the
#: joint the motion holds still; the world is the static reference.
PIVOT_RIG = rig_topology(("world", "camera"), [("joint", ("world", "camera"), "ball")], "world")


def bundle_adjust_fixed_joint(
    corners: FloatArray,
    valid: np.ndarray | None,
    board_points: FloatArray,
    intrinsics0: FloatArray,
    T_world_cam0: FloatArray,
    joint_in_cam0: FloatArray,
    joint_in_world0: FloatArray,
    *,
    model: str = "pinhole",
) -> FixedJointBundle:
    """Maximum-likelihood fixed-joint calibration of one camera from its corners: the rig
    bundle adjustment (:func:`bundle_adjust_rig`) of :data:`PIVOT_RIG`.

    The camera turns about a point fixed in its board's frame (the paper's fixed-joint
    motion, a pivot), so frame ``i``'s pose is ``[R_i, p_w - R_i o]`` (eq. (2) with the
    world as the static body): the unknowns are the intrinsics, the joint in the camera
    ``o`` and in the board ``p_w``, and each frame's rotation ``R_i``.

    Parameters
    ----------
    corners : ndarray, shape (n, m, 2)
        Detected corners of ``n`` frames (pixels), in board-point order; NaN where a
        frame did not see the corner.
    valid : ndarray of bool, shape (n, m), or None
        Which corners to use (besides the finite ones); None: every finite corner.
    board_points : ndarray, shape (m, 3)
        The corners in the board's frame (metres).
    intrinsics0 : ndarray, shape (p,)
        Initial intrinsics of ``model`` (e.g. from ``cv2.calibrateCamera``); the model's
        ``held`` ones (``k3`` of the pinhole model) stay as given.
    T_world_cam0 : ndarray, shape (n, 4, 4)
        Initial poses (e.g. from PnP); only their rotations are used.
    joint_in_cam0, joint_in_world0 : ndarray, shape (3,)
        Initial joint (e.g. from :func:`acs_cli.core.joint.estimate_joint_fixed`).
    model : {"pinhole", "rational", "fisheye"}

    Returns
    -------
    FixedJointBundle

    Raises
    ------
    InputError
        Shapes that do not fit, too few frames, or a frame with fewer than
        :data:`acs_cli.core.bundle.MIN_FRAME_CORNERS` corners.
    """
    corners = np.asarray(corners, dtype=float)
    n = corners.shape[0] if corners.ndim == 3 else 0
    seen = observed(corners, valid, np.asarray(board_points, dtype=float))
    T0 = se3.check_transforms(T_world_cam0, "initial poses")
    if T0.shape[0] != n:
        raise InputError(f"{T0.shape[0]} initial poses for {n} frames")
    o, p_w = (np.asarray(v, dtype=float).reshape(3) for v in (joint_in_cam0, joint_in_world0))
    T_world_cam = se3.transforms_from_rt(T0[:, :3, :3], p_w - se3.rotate(T0[:, :3, :3], o))
    edge = EdgeEstimate(
        joint=PIVOT_RIG.joints[0],
        position_in={"world": p_w, "camera": o},
        position_cov_in={},
        axis_in={},
        axis_std_deg_in={},
        T_q_p=np.eye(4),
        residual_rms=0.0,
        frames_used=n,
        frames_rejected=0,
        inliers=np.arange(n),
        noise={},
    )
    start = RigEstimate(
        topology=PIVOT_RIG,
        reference_frame=0,
        cameras={
            "world": CameraEstimate(
                None,
                np.zeros((6, 6)),
                poses_in_reference_world=np.broadcast_to(np.eye(4), (n, 4, 4)).copy(),
            ),
            "camera": CameraEstimate(None, np.zeros((6, 6)), poses_in_reference_world=T_world_cam),
        },
        edges={"joint": edge},
        cost=0.0,
        iterations=0,
    )
    views = CameraViews(
        corners,
        seen,
        np.asarray(board_points, dtype=float),
        np.asarray(intrinsics0, dtype=float),
        model,
    )
    size = camera_model(model).size
    if views.intrinsics.shape != (size,):
        raise InputError(f"the {model} model takes {size} intrinsics, got {views.intrinsics.shape}")
    ba = bundle_adjust_rig(
        PIVOT_RIG, {"camera": views}, start, np.arange(n), static=True, hold_intrinsics=False
    )
    e = ba.estimate.edges["joint"]
    return FixedJointBundle(
        model=model,
        intrinsics=ba.intrinsics["camera"],
        intrinsics_covariance=ba.intrinsics_covariance["camera"],
        joint_in_cam=e.position_in["camera"],
        joint_covariance=e.position_cov_in["camera"],
        joint_in_world=e.position_in["world"],
        rms_px=ba.rms_px["camera"],
        per_frame_rms_px=ba.per_frame_rms_px["camera"],
        sigma_px=ba.sigma_px,
        success=ba.success,
        correlated=ba.estimate.correlated,
    )
