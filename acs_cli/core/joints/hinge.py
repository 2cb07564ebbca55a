"""The hinge: a revolute joint.

An axis fixed in both bodies (``u_p``, ``u_q``, unit vectors) and a point on it, the same
physical point in both cameras: ``G_p o_p = G_q o_q`` and ``R_Gp u_p = R_Gq u_q`` at every
frame. The reported point is the axis point nearest camera ``p``'s centre
(``o_p . u_p = 0``), the axis's sign has its largest component in ``p`` positive (a rig
config may choose others after the solve: :func:`acs_cli.core.rig.oriented_axis`,
:func:`acs_cli.core.rig.hinge_point_from_nearest`).

Unknowns (9): ``o_p`` in the plane across ``u_p`` through ``p``'s centre (2), ``o_q`` (3),
and each axis as a 2-dof step ``u = unit(u0 + B a)`` from its starting direction ``u0``
(``B`` across ``u0``; the anchor is ``(u0_p, u0_q)``). The rig bundle's articulation is
the angle ``theta[i]`` (1 a frame): ``R_p_q[i] = A Rz(theta[i]) B`` with frames ``A`` (its
third column ``u_p``) and ``B`` (``u_q = B^T e_z``). URDF: one revolute joint.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from acs_cli.core import se3
from acs_cli.core.joints.base import (
    Edge,
    Geometry,
    JointModel,
    UrdfJoint,
    geometry_jacobian,
    point_jacobian,
    point_residual,
    point_start,
    tangent_basis,
    unit,
)
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError


def _rz(theta: FloatArray) -> FloatArray:
    """``(n, 3, 3)`` rotations about z by ``theta`` ``(n,)`` radians."""
    c, s = np.cos(theta), np.sin(theta)
    R = np.zeros((theta.size, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, -s, s, c
    R[:, 2, 2] = 1.0
    return R


def _across(v: FloatArray) -> FloatArray:
    """``(3,)`` rotation vector ``(v0, v1, 0)``: a turn across the local z axis."""
    return np.array([v[0], v[1], 0.0])


def _axis_geometry(
    e: FloatArray, anchor: Any
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """``o_p, o_q, u_p, u_q`` of a hinge's unknowns ``e`` (9,): the axes are steps
    ``u = unit(u0 + B a)`` from the starting directions ``anchor = (u0p, u0q)``; ``o_p`` lies
    in the plane across ``u_p`` through ``p``'s centre (the axis point nearest it)."""
    u0p, u0q = anchor
    Bp, Bq = tangent_basis(u0p), tangent_basis(u0q)
    up = unit(u0p + Bp @ e[5:7])
    uq = unit(u0q + Bq @ e[7:9])
    o_p = Bp @ e[:2]
    o_p = o_p - (o_p @ up) * up
    return o_p, e[2:5], up, uq


def _residual_axis_geometry(
    e: FloatArray, anchor: Any
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`_axis_geometry` with the point moved along the axis to the one nearest both
    cameras' centres together (least ``|o_p|^2 + |o_q|^2``).

    Any point of the axis satisfies the constraint, but the pose noise reaches the residual
    through the lever arms, so the point used must not depend on which camera is named
    first: this one is symmetric in ``p`` and ``q`` (swapping ``between`` changes no
    estimate), and the least-noisy point of the line. Priors and results keep the reported
    point (nearest ``p``'s centre)."""
    o_p, o_q, u_p, u_q = _axis_geometry(e, anchor)
    s = -0.5 * float(o_p @ u_p + o_q @ u_q)
    return o_p + s * u_p, o_q + s * u_q, u_p, u_q


class Hinge(JointModel):
    """A revolute joint (see the module doc)."""

    name = "hinge"
    n_params = 9  # o_p across its axis (2), o_q (3), the axes' steps (2 + 2)
    residual_kinds = ("pos", "rot")
    outlier_dim = 5  # 3 point rows, 2 axis rows (an axis difference has no radial part)
    noise_levels = 3  # theta_t, theta_r of the point rows, the axis rows' sigma
    rotation_dof = 2.0
    has_point = True
    has_axis = True
    single_axis_ok = True
    articulation_dof = 1
    bundle_params = 9

    def geometry(self, e: FloatArray, anchor: Any) -> Geometry:
        """``o_p, o_q`` and the unit axes ``u_p, u_q``; ``o_p`` is the axis point nearest
        ``p``'s centre."""
        return _axis_geometry(e, anchor)

    def residual_geometry(self, e: FloatArray, anchor: Any) -> Geometry:
        """The point moved along the axis to the one nearest both cameras' centres together
        (:func:`_residual_axis_geometry`)."""
        return _residual_axis_geometry(e, anchor)

    def start(
        self,
        Rp: FloatArray,
        tp: FloatArray,
        Rq: FloatArray,
        tq: FloatArray,
        point: tuple[FloatArray, FloatArray] | None,
    ) -> tuple[FloatArray, Any]:
        if point is None:
            sol = point_start(Rp, tp, Rq, tq)  # eq. (13)
            point = (sol[:3], sol[3:])
        # relative rotations R_p_q[i] = Rot(u_p, theta_i) R0: u_q with R_p_q u_q constant
        Rpq = np.einsum("nji,njk->nik", Rp, Rq)
        _, _, Vt = np.linalg.svd((Rpq - Rpq.mean(axis=0)).reshape(-1, 3), full_matrices=False)
        u_p, u_q = unit(Rpq.mean(axis=0) @ Vt[2]), Vt[2]
        # slide the point along the axis to the one nearest p's centre
        lam = -float(point[0] @ u_p)
        o_p, o_q = point[0] + lam * u_p, point[1] + lam * u_q
        return np.concatenate([tangent_basis(u_p).T @ o_p, o_q, np.zeros(4)]), (u_p, u_q)

    def residual_blocks(
        self,
        e: FloatArray,
        anchor: Any,
        Rp: FloatArray,
        tp: FloatArray,
        Rq: FloatArray,
        tq: FloatArray,
    ) -> dict[str, FloatArray]:
        o_p, o_q, u_p, u_q = _residual_axis_geometry(e, anchor)
        return {
            "pos": point_residual(o_p, o_q, Rp, tp, Rq, tq),  # eq. (24)
            "rot": se3.rotate(Rp, u_p) - se3.rotate(Rq, u_q),  # one axis
        }

    def jacobian(self, jc: Any) -> None:
        o_p, o_q, u_p, u_q = _residual_axis_geometry(jc.e, jc.anchor)
        Dg = geometry_jacobian(self, jc.e, jc.anchor, for_residuals=True)
        point_jacobian(jc, o_p, o_q, Dg)
        p, q, m = jc.p, jc.q, jc.m
        w = jc.w_rot * jc.mask
        wb = np.broadcast_to(w, (m, 3, 3)) * np.eye(3)
        jc.cam_block(p, se3.rotate(jc.Rp, u_p), 1.0, False, wb)
        jc.cam_block(q, se3.rotate(jc.Rq, u_q), -1.0, False, wb)
        Be = np.matmul(jc.RGp, Dg[6:9]) - np.matmul(jc.RGq, Dg[9:12])
        jc.put(w * Be)
        if jc.kk.size:
            i = int(jc.kk[0])
            for c, u, sign in ((p, u_p, 1.0), (q, u_q, -1.0)):
                if c in jc.Jd:
                    Dr = -sign * jc.W.R[jc.wk[c]] @ jc.meas[c][0][jc.k] @ se3.skew(u) @ jc.Jd[c]
                    jc.delta_block(c, i, w[i] * Dr, 0, 3)
        jc.next_block()

    def fixed_joint_prior(
        self, joint: Edge, camera: str, T_w_c: FloatArray, label: str
    ) -> dict[str, dict[str, Any]]:
        """The axis and its line (:func:`~acs_cli.core.joint.estimate_hinge_fixed`); the
        point itself when ``camera`` is the edge's first, whose nearest axis point the rig
        reports."""
        from acs_cli.core.joint import estimate_hinge_fixed

        h = estimate_hinge_fixed(T_w_c, label)
        axis = {camera: (h.axis_in_cam, max(float(np.radians(h.axis_std_deg)), 1e-6))}
        if camera == joint.between[0]:  # the rig's hinge point is the one nearest this camera
            return {
                "position_in": {camera: h.point_in_cam},
                "covariance_in": {camera: h.covariance_point + np.eye(3) * 1e-12},
                "axis_in": axis,
            }
        # only the line: the rig's point is nearest the other camera
        std = float(np.sqrt(max(np.linalg.eigvalsh(h.covariance_point)[-1], 1e-18)))
        return {"line_in": {camera: (h.point_in_cam, h.axis_in_cam, std)}, "axis_in": axis}

    def misfit(
        self, joint: Edge, blocks: dict[str, FloatArray], mask: np.ndarray
    ) -> tuple[float, str] | None:
        """The axis must stay one line in both bodies."""
        rms = float(np.degrees(np.sqrt(np.mean(np.sum(blocks["rot"][mask] ** 2, axis=1)))))
        p, q = joint.between
        return rms, (
            f"joint {joint.name} ({p}-{q}) is declared a hinge, but its axis moves by "
            f"{rms:.2f} deg RMS between the bodies: it bends about more than one axis "
            "(declare it type: ball)"
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
        u_p = geometry()[2]
        if abs(float(np.mean(se3.rotate(Rp, u_p), axis=0) @ axis)) < cos:
            return ""
        return (
            f"the offset between {p} and {q} along the hinge axis: both turn about that axis "
            "only (planar motion with the axis along the plane's normal)"
        )

    def position_hint_camera(self, joint: Edge) -> str | None:
        # the point is the one nearest p's centre: q's offset along the axis is the unknown
        return joint.between[1]

    def urdf(
        self,
        joint: Edge,
        parent: str,
        child: str,
        T_parent_child: FloatArray,
        axis: FloatArray | None,
    ) -> tuple[list[str], list[UrdfJoint], str]:
        p, q = joint.between
        return (
            [],
            [UrdfJoint(joint.name, "revolute", parent, child, T_parent_child, axis)],
            f"hinge {joint.name} ({p}-{q}): origin at the hinge point, axis in {child}'s frame",
        )

    def frames(self, e: FloatArray, geom0: dict[str, FloatArray]) -> dict[str, FloatArray]:
        """The rig bundle's ``A``, ``B``, ``o_p``, ``o_q`` from its unknowns ``e`` (9,)."""
        g0 = geom0
        A = g0["A"] @ se3.matrix_from_rotvec(_across(e[0:2]))
        B = se3.matrix_from_rotvec(_across(e[4:6])) @ g0["B"]
        return {"A": A, "B": B, "o_p": g0["o_p"] + g0["A"][:, :2] @ e[2:4],
                "o_q": g0["o_q"] + e[6:9]}  # fmt: skip

    def bundle_start(
        self,
        position_in: list[FloatArray],
        axis_p: FloatArray | None,
        T_q_p: FloatArray,
        T_p_q: FloatArray,
        k: int,
    ) -> tuple[FloatArray | None, dict[str, FloatArray], FloatArray, FloatArray]:
        if axis_p is None:
            raise InputError(
                "a hinge's bundle adjustment starts from its axis: the pose-based estimate "
                "gives none"
            )
        u_p = axis_p / np.linalg.norm(axis_p)
        A = np.column_stack([tangent_basis(u_p), u_p])
        if np.linalg.det(A) < 0:
            A[:, 0] *= -1.0
        B = A.T @ T_p_q[k, :3, :3]
        M = np.matmul(np.matmul(A.T, T_p_q[:, :3, :3]), B.T)  # about Rz(theta)
        theta = np.arctan2(M[:, 1, 0] - M[:, 0, 1], M[:, 0, 0] + M[:, 1, 1])[:, None]
        geom0 = {"A": A, "B": B, "o_p": position_in[0], "o_q": position_in[1]}
        return None, geom0, np.zeros(self.bundle_params), theta

    def bundle_edge(
        self, e: FloatArray, a: FloatArray, R0: Any, geom0: dict[str, FloatArray]
    ) -> tuple[FloatArray, FloatArray]:
        h = self.frames(e, geom0)
        R = np.matmul(np.matmul(h["A"], _rz(a[:, 0])), h["B"])
        return R, h["o_p"] - se3.rotate(R, h["o_q"])  # eq. (2): O_p = T_p_q O_q

    def bundle_geometry(self, e: FloatArray, R0: Any, geom0: dict[str, FloatArray]) -> FloatArray:
        h = self.frames(e, geom0)
        u_p, u_q = h["A"][:, 2], h["B"][2, :]
        shift = float(h["o_p"] @ u_p)  # the point nearest p's centre
        return np.concatenate([h["o_p"] - shift * u_p, h["o_q"] - shift * u_q, u_p, u_q])
