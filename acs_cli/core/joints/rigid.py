"""The rigid joint: both cameras on one body, ``T_q_p`` constant.

``G_p = G_q T_q_p`` at every frame: the hand-eye constraint, as a rotation residual
``log(R_Gp^T R_Gq R_q_p)`` and a translation residual at the midpoint between the two
cameras (symmetric in ``p`` and ``q``). Unknowns (6): a right step of ``R_q_p`` from its
start (the anchor) and ``t_q_p``. No articulation in the rig bundle; URDF: the two cameras
are one body (a fixed joint).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from acs_cli.core import se3
from acs_cli.core.joints.base import Edge, Geometry, JointModel
from acs_cli.core.se3 import FloatArray


class Rigid(JointModel):
    """A rigid mount (see the module doc)."""

    name = "rigid"
    n_params = 6  # R_q_p's step (3), t_q_p (3)
    residual_kinds = ("rot", "trans")
    outlier_dim = 6
    noise_levels = 2  # one sigma each of the rotation and translation rows
    rotation_dof = 3.0
    constant_transform = True
    articulation_dof = 0
    bundle_params = 6

    def geometry(self, e: FloatArray, anchor: Any) -> Geometry:
        raise ValueError("a rigid joint has no point or axis")

    def start(
        self,
        Rp: FloatArray,
        tp: FloatArray,
        Rq: FloatArray,
        tq: FloatArray,
        point: tuple[FloatArray, FloatArray] | None,
    ) -> tuple[FloatArray, Any]:
        # G_p = G_q T_q_p: T_q_p from the frames' average
        Rqp, _ = se3.project_to_rotation(np.einsum("nji,njk->ik", Rq, Rp))
        tqp = np.mean(np.einsum("nji,nj->ni", Rq, tp - tq), axis=0)
        return np.concatenate([np.zeros(3), tqp]), Rqp

    def transform(self, e: FloatArray, anchor: Any) -> FloatArray | None:
        return se3.transforms_from_rt(anchor @ se3.matrix_from_rotvec(e[:3]), e[3:6])

    def residual_blocks(
        self,
        e: FloatArray,
        anchor: Any,
        Rp: FloatArray,
        tp: FloatArray,
        Rq: FloatArray,
        tq: FloatArray,
    ) -> dict[str, FloatArray]:
        Rqp = anchor @ se3.matrix_from_rotvec(e[:3])
        out: dict[str, FloatArray] = {}
        # G_p = G_q T_q_p
        out["rot"] = se3.rotvec_from_matrix(np.einsum("nji,njk,kl->nil", Rp, Rq, Rqp))
        # G_p = G_q T_q_p, at the midpoint between the two cameras (symmetric in p and q:
        # swapping the edge's ends changes only the residual's sign)
        v = Rqp.T @ e[3:6]  # = -t_p_q
        out["trans"] = 0.5 * (se3.rotate(Rq, e[3:6]) + se3.rotate(Rp, v)) + tq - tp
        return out

    def jacobian(self, jc: Any) -> None:
        from acs_cli.core.bundle import right_jacobians  # here: the registry imports little

        e, p, q, m, W, L = jc.e, jc.p, jc.q, jc.m, jc.W, jc.L
        Rp, Rq, RGp, RGq, mask = jc.Rp, jc.Rq, jc.RGp, jc.RGq, jc.mask
        Rqp = jc.anchor @ se3.matrix_from_rotvec(e[:3])
        E = np.einsum("nji,njk,kl->nil", RGp, RGq, Rqp)
        rho = se3.rotvec_from_matrix(E)
        Ji = se3.right_jacobians_inv(rho) * jc.w_rot * mask
        Et = np.swapaxes(E, 1, 2)
        # q's similarity: E Exp((R_q R_qp)^T dw); p's: E Exp(-E^T R_p^T dw)
        for at, w_ in jc.by_world(q):
            if w_ in L.rot:
                A = np.swapaxes(np.matmul(Rq[at], Rqp), 1, 2)
                cols = list(range(L.rot[w_].start, L.rot[w_].stop))
                jc.put(np.matmul(Ji[at], A @ W.Jw[w_]), cols, at)
        for at, w_ in jc.by_world(p):
            if w_ in L.rot:
                A = -np.matmul(Et[at], np.swapaxes(Rp[at], 1, 2))
                cols = list(range(L.rot[w_].start, L.rot[w_].stop))
                jc.put(np.matmul(Ji[at], A @ W.Jw[w_]), cols, at)
        Jre = right_jacobians(e[None, :3])[0]
        blk = np.concatenate([np.matmul(Ji, Jre), np.zeros((m, 3, 3))], axis=2)
        jc.put(blk)
        Jd, k, meas, wk = jc.Jd, jc.k, jc.meas, jc.wk
        if jc.kk.size:
            i = int(jc.kk[0])
            if q in Jd:
                jc.delta_block(q, i, Ji[i] @ Rqp.T @ Jd[q], 0, 3)
            if p in Jd:
                jc.delta_block(p, i, -Ji[i] @ Et[i] @ Jd[p], 0, 3)
        jc.next_block()
        # translation at the midpoint: (R_Gq t_qp + R_Gp v) / 2 + t_Gq - t_Gp, v = R_qp^T t_qp
        tqp = e[3:6]
        v = Rqp.T @ tqp
        wt = jc.w_trans * mask
        wtb = np.broadcast_to(wt, (m, 3, 3)) * np.eye(3)
        yq = 0.5 * se3.rotate(Rq, tqp) + jc.sq_tq
        jc.cam_block(q, yq, 1.0, True, wtb)
        yp = jc.sp_tp - 0.5 * se3.rotate(Rp, v)
        jc.cam_block(p, yp, -1.0, True, wtb)
        # d(R_qp^T t) = [R_qp^T t]x Jr dw; d/dt_qp = (R_Gq + R_Gp R_qp^T) / 2
        d_rot = 0.5 * np.matmul(RGp, se3.skew(v) @ Jre)
        d_t = 0.5 * (RGq + np.matmul(RGp, Rqp.T))
        jc.put(wt * np.concatenate([d_rot, d_t], axis=2))
        if jc.kk.size:
            i = int(jc.kk[0])
            if q in Jd:
                RX, sc = W.R[wk[q]], W.s[wk[q]]
                Dr = -0.5 * RX @ meas[q][0][k] @ se3.skew(tqp) @ Jd[q]
                jc.delta_block(q, i, wt[i] * np.concatenate([Dr, sc * RX], axis=1), 0, 6)
            if p in Jd:
                RX, sc = W.R[wk[p]], W.s[wk[p]]
                Dr = -0.5 * RX @ meas[p][0][k] @ se3.skew(v) @ Jd[p]
                jc.delta_block(p, i, wt[i] * np.concatenate([Dr, -sc * RX], axis=1), 0, 6)
        jc.next_block()

    def misfit(
        self, joint: Edge, blocks: dict[str, FloatArray], mask: np.ndarray
    ) -> tuple[float, str] | None:
        """The cameras must not turn relative to each other (``R_p^T R_q`` constant)."""
        rms = float(np.degrees(np.sqrt(np.mean(np.sum(blocks["rot"][mask] ** 2, axis=1)))))
        p, q = joint.between
        return rms, (
            f"joint {joint.name} ({p}-{q}) is declared rigid, but the two bodies turn "
            f"relative to each other by {rms:.2f} deg RMS: a ball or a hinge?"
        )

    def planar_offset(
        self,
        joint: Edge,
        Rp: FloatArray,
        Rq: FloatArray,
        geometry: Any,
        axis: FloatArray,
        cos: float,
    ) -> str:
        p, q = joint.between
        return (
            f"the offset between {p} and {q} along the axis {p} turns about (a rigid pair that "
            "turns about one axis only, planar motion)"
        )

    def bundle_start(
        self,
        position_in: list[FloatArray],
        axis_p: FloatArray | None,
        T_q_p: FloatArray,
        T_p_q: FloatArray,
        k: int,
    ) -> tuple[FloatArray | None, dict[str, FloatArray], FloatArray, FloatArray]:
        T = se3.invert_transforms(T_q_p)
        return (
            T[:3, :3],
            {"t": T[:3, 3]},
            np.zeros(self.bundle_params),
            np.zeros((T_p_q.shape[0], 0)),
        )

    def bundle_edge(
        self, e: FloatArray, a: FloatArray, R0: Any, geom0: dict[str, FloatArray]
    ) -> tuple[FloatArray, FloatArray]:
        n = a.shape[0]
        R1 = R0 @ se3.matrix_from_rotvec(e[:3])
        return np.broadcast_to(R1, (n, 3, 3)), np.broadcast_to(geom0["t"] + e[3:], (n, 3))
