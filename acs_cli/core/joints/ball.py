"""The ball joint: a spherical joint, the paper's model.

Fixed at ``o_p`` in camera ``p``'s frame and at ``o_q`` in ``q``'s, whatever the
articulation: ``G_p o_p = G_q o_q`` at every frame (eq. (24)). Unknowns ``(o_p, o_q)``
(6); the rig bundle's articulation is the rotation ``R_p_q[i]`` (3 a frame), with
``T_p_q[i] = [R_p_q[i], o_p - R_p_q[i] o_q]`` (eq. (2)). URDF: three revolute joints
about the child body's x, y and z axes through the centre.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from acs_cli.core import se3
from acs_cli.core.joints.base import (
    SINGLE_AXIS_RATIO,
    Edge,
    Geometry,
    JointModel,
    UrdfJoint,
    geometry_jacobian,
    point_jacobian,
    point_residual,
    point_start,
    single_axis,
)
from acs_cli.core.se3 import FloatArray


class Ball(JointModel):
    """A spherical joint (see the module doc)."""

    name = "ball"
    n_params = 6  # o_p, o_q
    residual_kinds = ("pos",)
    outlier_dim = 3
    noise_levels = 2  # theta_t, theta_r of the point rows
    has_point = True
    point_tells_rotation_noise = True
    pair_start = True
    articulation_dof = 3
    bundle_params = 6

    def geometry(self, e: FloatArray, anchor: Any) -> Geometry:
        return e[:3], e[3:6], None, None

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
        return np.concatenate([point[0], point[1]]), None

    def residual_blocks(
        self,
        e: FloatArray,
        anchor: Any,
        Rp: FloatArray,
        tp: FloatArray,
        Rq: FloatArray,
        tq: FloatArray,
    ) -> dict[str, FloatArray]:
        o_p, o_q, _, _ = self.residual_geometry(e, anchor)
        return {"pos": point_residual(o_p, o_q, Rp, tp, Rq, tq)}

    def jacobian(self, jc: Any) -> None:
        o_p, o_q, _, _ = self.residual_geometry(jc.e, jc.anchor)
        point_jacobian(jc, o_p, o_q, geometry_jacobian(self, jc.e, jc.anchor, for_residuals=True))

    def seed_point(self, e: FloatArray, side: int, position: FloatArray) -> None:
        e[3 * side : 3 * side + 3] = position

    def fixed_joint_prior(
        self, joint: Edge, camera: str, T_w_c: FloatArray, label: str
    ) -> dict[str, dict[str, Any]]:
        """The centre by pivot calibration (:func:`~acs_cli.core.joint.estimate_pivot`)."""
        from acs_cli.core.joint import estimate_pivot

        pv = estimate_pivot(T_w_c, "refined", label)
        return {
            "position_in": {camera: pv.position_in_cam},
            "covariance_in": {camera: pv.covariance},
        }

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
        b = single_axis(np.einsum("nji,njk->nik", Rp, Rq))
        if b is None:
            return ""
        if abs(float(np.mean(se3.rotate(Rp, b), axis=0) @ axis)) < cos:
            return ""
        return (
            f"the offset between {p} and {q} along the vertical of the motion: the rig turns "
            f"and joint {joint.name} bends about that axis only (planar motion)"
        )

    def motion_advice(self, joint: Edge, Rst: FloatArray) -> list[str]:
        s = np.linalg.svd((Rst - Rst.mean(axis=0)).reshape(-1, 3), compute_uv=False)
        if s[2] < SINGLE_AXIS_RATIO * s[0]:
            return [f"joint {joint.name} bends about one axis only: declare it type: hinge"]
        return []

    def position_hint_camera(self, joint: Edge) -> str | None:
        # a ball seen from a camera turning about one axis: that camera's
        return joint.between[0]

    def urdf(
        self,
        joint: Edge,
        parent: str,
        child: str,
        T_parent_child: FloatArray,
        axis: FloatArray | None,
    ) -> tuple[list[str], list[UrdfJoint], str]:
        name, (p, q) = joint.name, joint.between
        eye = np.eye(4)
        links = [f"{name}_x_link", f"{name}_y_link"]
        joints = [
            UrdfJoint(f"{name}_x", "revolute", parent, links[0], T_parent_child, np.eye(3)[0]),
            UrdfJoint(f"{name}_y", "revolute", links[0], links[1], eye, np.eye(3)[1]),
            UrdfJoint(f"{name}_z", "revolute", links[1], child, eye, np.eye(3)[2]),
        ]
        comment = (
            f"ball joint {name} ({p}-{q}) as three revolute joints about the x, y and z axes of "
            f"{child} through its centre, "
            f"joined by the massless links {links[0]} and {links[1]} (a floating joint would "
            "also translate)"
        )
        return links, joints, comment

    def bundle_start(
        self,
        position_in: list[FloatArray],
        axis_p: FloatArray | None,
        T_q_p: FloatArray,
        T_p_q: FloatArray,
        k: int,
    ) -> tuple[FloatArray | None, dict[str, FloatArray], FloatArray, FloatArray]:
        n = T_p_q.shape[0]
        return T_p_q[:, :3, :3], {}, np.concatenate(position_in), np.zeros((n, 3))

    def bundle_edge(
        self, e: FloatArray, a: FloatArray, R0: Any, geom0: dict[str, FloatArray]
    ) -> tuple[FloatArray, FloatArray]:
        R = np.matmul(R0, se3.matrix_from_rotvec(a))
        o_p, o_q = e[:3], e[3:6]
        return R, o_p - se3.rotate(R, o_q)  # eq. (2): O_p = T_p_q O_q

    def bundle_geometry(self, e: FloatArray, R0: Any, geom0: dict[str, FloatArray]) -> FloatArray:
        return e.copy()
