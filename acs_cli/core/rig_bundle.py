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

Camera ``c``'s pose is chained along the tree, ``T_ref_c[i]`` (as
:func:`acs_cli.core.rig.chain_transforms`), so a corner ``X`` of its board is at

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
information, scaled by the fitted corner noise.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from acs_cli.core import lsq, se3
from acs_cli.core.bundle import check_frame_corners, information, observed
from acs_cli.core.camera_models import camera_model
from acs_cli.core.rig import RigJoint, RigTopology
from acs_cli.core.rig_solve import CameraEstimate, RigEstimate, tangent_basis
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

__all__ = ["MIN_RIG_BUNDLE_FRAMES", "CameraViews", "RigBundle", "bundle_adjust_rig"]

#: Fewest frames (every camera seeing its board) a rig's bundle adjustment takes.
MIN_RIG_BUNDLE_FRAMES = 6
#: Unknowns per frame of each joint type's articulation.
ARTICULATION_DOF = {"ball": 3, "hinge": 1, "rigid": 0}
#: Unknowns of each joint type's fixed geometry.
GEOMETRY_DOF = {"ball": 6, "hinge": 9, "rigid": 6}


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
class RigBundle:
    """Result of :func:`bundle_adjust_rig`.

    Attributes
    ----------
    estimate : RigEstimate
        The rig with the bundle's ``T_cam_ref`` (and covariances), joints and boards'
        frames; each camera's measured poses mapped by its refined board frame, and at the
        reference instant the bundle's pose. The joints' ``residual_rms``, frame counts,
        inliers and noise stay those of the pose-based solve.
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
    """

    estimate: RigEstimate
    intrinsics: dict[str, FloatArray]
    intrinsics_std: dict[str, FloatArray]
    intrinsics_covariance: dict[str, FloatArray]
    rms_px: dict[str, float]
    sigma_px: float
    frames: np.ndarray
    success: bool


class _Layout:
    """Where each unknown lives: shared ones first, then one block per frame."""

    def __init__(self, topo: RigTopology, n: int, free: dict[str, list[int]]) -> None:
        k = 0
        self.free = free  # per camera: indices of its refined intrinsics
        self.intr = {}
        for c in topo.cameras:
            self.intr[c] = slice(k, k + len(free[c]))
            k += len(free[c])
        self.world = {}
        for c in topo.cameras:
            if c != topo.reference:
                self.world[c] = slice(k, k + 6)
                k += 6
        self.geom = {}
        for j in topo.joints:
            self.geom[j.name] = slice(k, k + GEOMETRY_DOF[j.type])
            k += GEOMETRY_DOF[j.type]
        self.n_shared = k
        f = 6  # the reference camera's pose G[i]
        self.art = {}
        for j in topo.joints:
            self.art[j.name] = slice(f, f + ARTICULATION_DOF[j.type])
            f += ARTICULATION_DOF[j.type]
        self.block = f
        self.n = n
        self.size = k + f * n

    def frame_columns(self, i: int, sl: slice) -> list[int]:
        start = self.n_shared + self.block * i
        return list(range(start + sl.start, start + sl.stop))


def _rz(theta: FloatArray) -> FloatArray:
    """``(n, 3, 3)`` rotations about z by ``theta`` ``(n,)`` radians."""
    c, s = np.cos(theta), np.sin(theta)
    R = np.zeros((theta.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, -s, s, c
    R[:, 2, 2] = 1.0
    return R


def _apply(R: FloatArray, v: FloatArray) -> FloatArray:
    """``R_i v_i`` for stacks ``(n, 3, 3)`` and ``(n, 3)``."""
    return np.einsum("nij,nj->ni", R, v)


def _across(v: FloatArray) -> FloatArray:
    """``(3,)`` rotation vector ``(v0, v1, 0)``: a turn across the local z axis."""
    return np.array([v[0], v[1], 0.0])


@dataclass
class _Model:
    """The starting point and everything the residuals need besides the unknowns."""

    topo: RigTopology
    L: _Layout
    views: dict[str, CameraViews]
    frames: np.ndarray  # timeline indices adjusted
    G0: FloatArray  # (n, 4, 4) reference camera in its board's frame
    W0: dict[str, FloatArray]  # (4, 4) per non-reference camera
    R0: dict[str, FloatArray]  # per ball (n, 3, 3) articulations; per rigid (3, 3)
    geom0: dict[str, dict[str, FloatArray]]  # per joint: starting geometry
    obs: dict[str, tuple[np.ndarray, np.ndarray, FloatArray]]  # frame, corner, pixels

    def intrinsics(self, x: FloatArray, c: str) -> FloatArray:
        out = np.asarray(self.views[c].intrinsics, dtype=float).copy()
        out[self.L.free[c]] = x[self.L.intr[c]]
        return out

    def hinge(self, x: FloatArray, name: str) -> dict[str, FloatArray]:
        """A hinge's ``A``, ``B``, ``o_p``, ``o_q`` at ``x``."""
        g0, e = self.geom0[name], x[self.L.geom[name]]
        A = g0["A"] @ se3.matrix_from_rotvec(_across(e[0:2]))
        B = se3.matrix_from_rotvec(_across(e[4:6])) @ g0["B"]
        return {"A": A, "B": B, "o_p": g0["o_p"] + g0["A"][:, :2] @ e[2:4],
                "o_q": g0["o_q"] + e[6:9]}  # fmt: skip

    def edge(self, x: FloatArray, j: RigJoint, blocks: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``T_p_q`` of every frame: rotations ``(n, 3, 3)``, translations ``(n, 3)``."""
        e, a = x[self.L.geom[j.name]], blocks[:, self.L.art[j.name]]
        n = blocks.shape[0]
        if j.type == "rigid":
            R1 = self.R0[j.name] @ se3.matrix_from_rotvec(e[:3])
            return np.broadcast_to(R1, (n, 3, 3)), np.broadcast_to(
                self.geom0[j.name]["t"] + e[3:], (n, 3)
            )
        if j.type == "ball":
            R = np.matmul(self.R0[j.name], se3.matrix_from_rotvec(a))
            o_p, o_q = e[:3], e[3:6]
        else:
            h = self.hinge(x, j.name)
            R = np.matmul(np.matmul(h["A"], _rz(a[:, 0])), h["B"])
            o_p, o_q = h["o_p"], h["o_q"]
        return R, o_p - se3.rotate(R, o_q)  # eq. (2): O_p = T_p_q O_q

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
        RG = np.matmul(self.G0[:, :3, :3], se3.matrix_from_rotvec(blocks[:, :3]))
        tG = self.G0[:, :3, 3] + blocks[:, 3:6]
        return {c: (np.matmul(RG, R), tG + _apply(RG, t)) for c, (R, t) in self.chain(x).items()}

    def board(self, x: FloatArray, c: str) -> tuple[FloatArray, FloatArray]:
        """``W_c``: camera ``c``'s board frame in the reference board's frame."""
        if c == self.topo.reference:
            return np.eye(3), np.zeros(3)
        w = x[self.L.world[c]]
        W0 = self.W0[c]
        return W0[:3, :3] @ se3.matrix_from_rotvec(w[:3]), W0[:3, 3] + w[3:]

    def residuals(self, x: FloatArray) -> FloatArray:
        """Pixel residuals, camera by camera in ``topo.cameras`` order (as
        :meth:`row_frames`), each in its observations' order."""
        out = []
        poses = self.poses(x)
        for c in self.topo.cameras:
            R, t = poses[c]
            fi, ki, px = self.obs[c]
            Rw, tw = self.board(x, c)
            Xw = self.views[c].board_points[ki] @ Rw.T + tw
            x_cam = np.einsum("kji,kj->ki", R[fi], Xw - t[fi])  # R^T (W X - t)
            cam = camera_model(self.views[c].model)
            out.append((cam.project(x_cam, self.intrinsics(x, c)) - px).ravel())
        return np.concatenate(out)

    def row_frames(self) -> np.ndarray:
        """The frame of each residual row (the order of :meth:`residuals`)."""
        return np.concatenate([np.repeat(self.obs[c][0], 2) for c in self.topo.cameras])


def _check(topo: RigTopology, views: dict[str, CameraViews], est: RigEstimate) -> int:
    """The timeline's length; ``InputError`` naming what does not fit."""
    missing = [c for c in topo.cameras if c not in views]
    if missing:
        raise InputError(f"no corners for camera(s) {', '.join(missing)}")
    n = views[topo.reference].corners.shape[0]
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
            raise InputError(f"camera {c}: {v.corners.shape[0]} instants, the reference {n}")
    if est.cameras[topo.reference].poses_in_reference_world.shape[0] != n:
        raise InputError("the rig estimate and the corners are on different timelines")
    return n


def _initial(
    topo: RigTopology, views: dict[str, CameraViews], est: RigEstimate, frames: np.ndarray
) -> tuple[_Model, FloatArray]:
    """The model and its starting unknowns, from the pose-based estimate."""
    L = _Layout(topo, frames.size, {c: camera_model(views[c].model).free() for c in topo.cameras})
    G = {c: est.cameras[c].poses_in_reference_world[frames] for c in topo.cameras}
    x = np.zeros(L.size)
    blocks = np.zeros((frames.size, L.block))
    R0: dict[str, FloatArray] = {}
    geom0: dict[str, dict[str, FloatArray]] = {}
    for j in topo.joints:
        p, q = j.between
        e = est.edges[j.name]
        T_p_q = np.matmul(se3.invert_transforms(G[p]), G[q])
        if j.type == "rigid":
            T = se3.invert_transforms(e.T_q_p)
            R0[j.name], geom0[j.name] = T[:3, :3], {"t": T[:3, 3]}
        elif j.type == "ball":
            R0[j.name] = T_p_q[:, :3, :3]
            x[L.geom[j.name]] = np.concatenate([e.position_in[p], e.position_in[q]])
        else:
            u_p = e.axis_in[p] / np.linalg.norm(e.axis_in[p])
            A = np.column_stack([tangent_basis(u_p), u_p])
            if np.linalg.det(A) < 0:
                A[:, 0] *= -1.0
            k = int(np.flatnonzero(frames == est.reference_frame)[0])
            B = A.T @ T_p_q[k, :3, :3]
            M = np.matmul(np.matmul(A.T, T_p_q[:, :3, :3]), B.T)  # about Rz(theta)
            blocks[:, L.art[j.name]] = np.arctan2(M[:, 1, 0] - M[:, 0, 1], M[:, 0, 0] + M[:, 1, 1])[
                :, None
            ]
            geom0[j.name] = {"A": A, "B": B, "o_p": e.position_in[p], "o_q": e.position_in[q]}
    intr = np.zeros(L.n_shared)
    for c in topo.cameras:
        intr[L.intr[c]] = np.asarray(views[c].intrinsics, float)[L.free[c]]
    x[: L.n_shared] += intr
    x[L.n_shared :] = blocks.ravel()
    obs = {}
    for c in topo.cameras:
        v = views[c]
        fi, ki = np.nonzero(observed(v.corners, v.valid, v.board_points)[frames])
        obs[c] = (fi, ki, v.corners[frames][fi, ki])
    model = _Model(
        topo=topo,
        L=L,
        views=views,
        frames=frames,
        G0=G[topo.reference],
        W0={c: est.cameras[c].world_to_reference_world for c in topo.cameras},
        R0=R0,
        geom0=geom0,
        obs=obs,
    )
    return model, x


def bundle_adjust_rig(
    topology: RigTopology,
    views: dict[str, CameraViews],
    initial: RigEstimate,
    frames: np.ndarray,
) -> RigBundle:
    """Maximum-likelihood calibration of a rig from every camera's board corners.

    Parameters
    ----------
    topology : RigTopology
    views : dict of CameraViews
        Every camera's corners on the rig's timeline (metric boards).
    initial : RigEstimate
        The pose-based estimate (:func:`acs_cli.core.rig_solve.estimate_rig`) on the same
        timeline, metric (every camera of known scale).
    frames : ndarray of int
        The instants to adjust (every camera sees its board there); they must include the
        reference instant.

    Returns
    -------
    RigBundle

    Raises
    ------
    InputError
        Views that do not fit the topology or the timeline, an unknown scale, too few
        frames, or frames without the reference instant.
    DegenerateMotionError
        Corners that leave part of the rig undetermined.
    """
    n_total = _check(topology, views, initial)
    frames = np.unique(np.asarray(frames, dtype=int))
    if frames.size < MIN_RIG_BUNDLE_FRAMES:
        raise InputError(
            f"{frames.size} frames where every camera sees its board; the rig's bundle "
            f"adjustment needs at least {MIN_RIG_BUNDLE_FRAMES}"
        )
    if frames[0] < 0 or frames[-1] >= n_total or initial.reference_frame not in frames:
        raise InputError("the frames must be on the timeline and include the reference instant")
    for c, v in views.items():
        seen = observed(v.corners, v.valid, v.board_points, f"camera {c}'s corners")
        check_frame_corners(seen[frames], f"camera {c}", frames)
    unknown = [c for c, e in initial.cameras.items() if e.scale_std is not None]
    if unknown:
        raise InputError(
            f"camera(s) {', '.join(unknown)} have an unknown scale; corners are metric"
        )
    model, x0 = _initial(topology, views, initial, frames)
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

    sol = lsq.solve(fun, x0, jac=jac, method="normal")
    x = sol.x
    r = sol.fun.reshape(-1, 2)
    dof = max(sol.fun.size - x.size, 1)
    sigma2 = float(sol.fun @ sol.fun / dof)
    k_ref = int(np.flatnonzero(frames == initial.reference_frame)[0])
    cols = list(range(L.n_shared)) + L.frame_columns(k_ref, slice(0, L.block))
    cov = sigma2 * _inverse_columns(sol.jac, cols)
    where = {c: i for i, c in enumerate(cols)}
    est = _assemble(model, x, cov, where, k_ref, initial)
    intr = {c: model.intrinsics(x, c) for c in topology.cameras}
    std: dict[str, FloatArray] = {}
    icov: dict[str, FloatArray] = {}
    for c in topology.cameras:
        ci = np.zeros((intr[c].size, intr[c].size))
        idx = [where[i] for i in range(L.intr[c].start, L.intr[c].stop)]
        ci[np.ix_(L.free[c], L.free[c])] = cov[np.ix_(idx, idx)]
        icov[c] = ci
        std[c] = np.sqrt(np.maximum(np.diag(ci), 0.0))
    rms, start = {}, 0
    for c in topology.cameras:
        m = model.obs[c][0].size
        rc = r[start : start + m]
        rms[c] = float(np.sqrt(np.mean(np.sum(rc**2, axis=1)))) if m else 0.0
        start += m
    return RigBundle(est, intr, std, icov, rms, float(np.sqrt(sigma2)), frames, bool(sol.success))


def _relative(T_q_ref: FloatArray | None, T_p_ref: FloatArray | None) -> FloatArray:
    """``T_q_p`` from two ``T_cam_ref`` (every camera of a bundle has one)."""
    if T_q_ref is None or T_p_ref is None:
        raise ValueError("a camera of the bundle has no pose at the reference instant")
    return T_q_ref @ se3.invert_transforms(T_p_ref)


def _inverse_columns(J: object, cols: list[int]) -> FloatArray:
    """``(J^T J)^-1`` restricted to ``cols`` (rows and columns), by a Cholesky solve of the
    column-scaled information for those columns only; ``DegenerateMotionError`` when the
    information is singular."""
    H = information(J)
    d = 1.0 / np.sqrt(np.maximum(np.diag(H), 1e-300))  # unit diagonal: far better conditioned
    E = np.zeros((H.shape[0], len(cols)))
    E[cols, np.arange(len(cols))] = d[cols]
    try:
        X = d[:, None] * scipy.linalg.cho_solve(scipy.linalg.cho_factor(H * np.outer(d, d)), E)
    except np.linalg.LinAlgError:
        raise DegenerateMotionError(
            "the corners do not determine the rig (its information matrix is singular: a "
            "joint or a board that the motion cannot see)",
        ) from None
    return np.asarray(X[cols])


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
    cams: dict[str, CameraEstimate] = {}
    for c in topo.cameras:
        c0 = initial.cameras[c]
        T0 = T_cam_ref(x, c)
        cols: list[int] = []
        for s in topo.path(topo.reference, c):
            cols += list(range(L.n_shared))[L.geom[s.joint.name]]
            cols += L.frame_columns(k_ref, L.art[s.joint.name])

        def vec(xx: FloatArray, c: str = c, T0: FloatArray = T0) -> FloatArray:
            T = T_cam_ref(xx, c)
            return np.concatenate([se3.rotvec_from_matrix(T0[:3, :3].T @ T[:3, :3]), T[:3, 3]])

        C6 = lsq.propagate(vec, x, cols, sub(cols))[1] if cols else np.zeros((6, 6))
        # every measured pose mapped into the reference world by the refined board frame (as
        # the pose-based solve maps them by its own), and at the reference instant the
        # bundle's pose, which T_cam_ref describes
        Rw, tw = model.board(x, c)
        W = se3.transforms_from_rt(Rw, tw)
        world = np.matmul(W @ se3.invert_transforms(c0.world_to_reference_world),
                          c0.poses_in_reference_world)  # fmt: skip
        R_k, t_k = poses[c]
        world[initial.reference_frame] = se3.transforms_from_rt(R_k[k_ref], t_k[k_ref])
        cams[c] = dataclasses.replace(
            c0,
            T_cam_ref=T0,
            covariance=C6,
            poses_in_reference_world=world,
            world_to_reference_world=W,
        )
    edges = {}
    for j in topo.joints:
        p, q = j.between
        e0 = initial.edges[j.name]
        cols = list(range(L.n_shared))[L.geom[j.name]]
        T_q_p = _relative(cams[q].T_cam_ref, cams[p].T_cam_ref)
        if j.type == "rigid":
            edges[j.name] = dataclasses.replace(e0, T_q_p=T_q_p)
            continue

        def geometry(xx: FloatArray, j: RigJoint = j) -> FloatArray:
            if j.type == "ball":
                return xx[L.geom[j.name]].copy()
            h = model.hinge(xx, j.name)
            u_p, u_q = h["A"][:, 2], h["B"][2, :]
            shift = float(h["o_p"] @ u_p)  # the point nearest p's centre
            return np.concatenate([h["o_p"] - shift * u_p, h["o_q"] - shift * u_q, u_p, u_q])

        g, Cg = lsq.propagate(geometry, x, cols, sub(cols))
        pos = {p: g[:3], q: g[3:6]}
        pcov = {p: Cg[:3, :3], q: Cg[3:6, 3:6]}
        axis: dict[str, FloatArray] = {}
        astd: dict[str, float] = {}
        if j.type == "hinge":
            # one convention for the axis's sign (as the pose-based solve): its largest
            # component in p is positive
            sign = 1.0 if g[6 + int(np.argmax(np.abs(g[6:9])))] >= 0 else -1.0
            axis = {p: sign * g[6:9], q: sign * g[9:12]}
            astd = {
                p: float(np.degrees(np.sqrt(max(np.trace(Cg[6:9, 6:9]), 0.0)))),
                q: float(np.degrees(np.sqrt(max(np.trace(Cg[9:12, 9:12]), 0.0)))),
            }
        edges[j.name] = dataclasses.replace(
            e0, position_in=pos, position_cov_in=pcov, axis_in=axis, axis_std_deg_in=astd,
            T_q_p=T_q_p,
        )  # fmt: skip
    return dataclasses.replace(initial, cameras=cams, edges=edges)
