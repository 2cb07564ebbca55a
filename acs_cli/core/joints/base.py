"""What a joint type is to acscal: one :class:`JointModel` per type.

A rig's edge ``between: [p, q]`` has a joint type; everything that depends on the type
lives in that type's module (:mod:`.ball`, :mod:`.hinge`, :mod:`.rigid`) as one
:class:`JointModel`, and the engine asks the registry (:func:`acs_cli.core.joints.joint_model`)
instead of testing the type's name:

- its unknowns in the rig solve (:attr:`JointModel.n_params`) and what they mean
  (:meth:`JointModel.geometry`);
- its constraint residuals at every frame (:meth:`JointModel.residual_blocks`, the kinds
  :attr:`JointModel.residual_kinds`, 3 rows a frame each) and their Jacobian
  (:meth:`JointModel.jacobian`);
- its starting guess from poses already in one world (:meth:`JointModel.start`);
- its outputs: a point (``position_in``), an axis (``axis_in``) or a constant transform
  (``T_q_p``) (:attr:`JointModel.has_point`, :attr:`JointModel.has_axis`,
  :attr:`JointModel.constant_transform`);
- its URDF joints (:meth:`JointModel.urdf`);
- its degeneracy checks (:meth:`JointModel.misfit`, :meth:`JointModel.planar_offset`,
  :meth:`JointModel.motion_advice`) and the rig bundle's articulation
  (:attr:`JointModel.articulation_dof`, :meth:`JointModel.bundle_start`,
  :meth:`JointModel.bundle_edge`, :meth:`JointModel.bundle_geometry`).

Geometry ``g = (o_p, o_q, u_p, u_q)``: the joint's point in ``p``'s and ``q``'s frames
(reference units) and its unit axis in each, None where the type has none. Rotations act
on the right (``R @ Exp(theta)``, docs/conventions.md). This package is pure numpy.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from acs_cli.core import se3
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError

#: ``(o_p, o_q, u_p, u_q)``: a joint's point in ``p`` and ``q`` ``(3,)`` each, and its unit
#: axes ``(3,)`` (None for a type without an axis).
Geometry = tuple[FloatArray, FloatArray, "FloatArray | None", "FloatArray | None"]


#: Rotations "turn about one axis only" when the weakest singular value of their stacked,
#: centred matrices is below this fraction of the strongest (about 3 degrees of wobble per
#: 60 degrees of turning).
SINGLE_AXIS_RATIO = 0.05


def unit(v: FloatArray) -> FloatArray:
    """``v / |v|`` (``(3,)``), safe at zero."""
    return v / max(float(np.linalg.norm(v)), 1e-300)


def tangent_basis(u: FloatArray) -> FloatArray:
    """``(3, 2)``: two unit vectors across the unit vector ``u`` (and across each other).

    ``b1 = unit(u x e_k)`` with ``e_k`` the axis ``u`` is least along, ``b2 = u x b1``. In
    scalar arithmetic: the joints' geometry Jacobians (central differences) call this tens of
    thousands of times a solve, where numpy's per-call overhead on 3-vectors dominated."""
    x, y, z = float(u[0]), float(u[1]), float(u[2])
    ax, ay, az = abs(x), abs(y), abs(z)
    if ax <= ay and ax <= az:  # u x e_x
        c1, c2, c3 = 0.0, z, -y
    elif ay <= az:  # u x e_y
        c1, c2, c3 = -z, 0.0, x
    else:  # u x e_z
        c1, c2, c3 = y, -x, 0.0
    n = max(math.sqrt(c1 * c1 + c2 * c2 + c3 * c3), 1e-300)
    c1, c2, c3 = c1 / n, c2 / n, c3 / n
    return np.array(
        [[c1, y * c3 - z * c2], [c2, z * c1 - x * c3], [c3, x * c2 - y * c1]], dtype=float
    )


def single_axis(R: FloatArray) -> FloatArray | None:
    """The world axis ``(3,)`` of rotations ``(n, 3, 3)`` that turn about one axis only, or
    None. (The axis ``v`` in the body with ``R_i v`` constant; ``mean(R_i) v`` in the world.)"""
    _, s, Vt = np.linalg.svd((R - R.mean(axis=0)).reshape(-1, 3), full_matrices=False)
    if s[0] <= 0 or s[2] >= SINGLE_AXIS_RATIO * s[0]:
        return None
    return unit(R.mean(axis=0) @ Vt[2])


def point_residual(
    o_p: FloatArray, o_q: FloatArray, Rp: FloatArray, tp: FloatArray, Rq: FloatArray, tq: FloatArray
) -> FloatArray:
    """``(m, 3)``: ``G_p o_p - G_q o_q`` for poses ``G`` ``(m, 3, 3)``, ``(m, 3)`` in one
    world: the joint is one point (the paper's eq. (24))."""
    return (se3.rotate(Rp, o_p) + tp) - (se3.rotate(Rq, o_q) + tq)  # eq. (24)


def point_start(Rp: FloatArray, tp: FloatArray, Rq: FloatArray, tq: FloatArray) -> FloatArray:
    """``(6,)`` ``(o_p, o_q)`` by the paper's Algorithm I from poses ``(m, 3, 3)``,
    ``(m, 3)`` in one world: eq. (9), ``R_p o_p - R_q o_q = t_q - t_p``, linear
    (:func:`acs_cli.core.paper.algorithm_1_solve`)."""
    from acs_cli.core.paper import algorithm_1_solve  # here: the registry imports little

    x, _ = algorithm_1_solve(se3.transforms_from_rt(Rp, tp), se3.transforms_from_rt(Rq, tq))
    return np.asarray(x)


class Edge(Protocol):
    """A rig's edge as the models see it (:class:`acs_cli.core.rig.RigJoint` is one)."""

    @property
    def name(self) -> str: ...
    @property
    def between(self) -> tuple[str, str]: ...
    @property
    def type(self) -> str: ...


class EdgeJacobian(Protocol):
    """What :meth:`JointModel.jacobian` is given for one edge over its ``m`` frames (built by
    the rig solve, :mod:`acs_cli.core.rig_solve`). ``G_c = [R_X R_c, s R_X t_c + t_X]``."""

    e: FloatArray  # (n_params,) the edge's unknowns
    anchor: Any  # the type's fixed data from :meth:`JointModel.start`
    p: str
    q: str
    m: int
    Rp: FloatArray  # (m, 3, 3) measured rotations of p (the reference instant's corrected)
    Rq: FloatArray
    RGp: FloatArray  # (m, 3, 3) rotations of G_p
    RGq: FloatArray
    sp_tp: FloatArray  # (m, 3) p's measured translations times its world's scale
    sq_tq: FloatArray
    mask: FloatArray  # (m, 1, 1) inlier mask times the reference instant's gain
    kk: np.ndarray  # the reference instant's row in the edge, if any (0 or 1 entries)
    k: int  # the reference instant
    whiten_pos: FloatArray  # (m, 3, 3) whiteners of the point rows (in the edge's frame)
    w_rot: float  # 1 / sigma of the rotation (axis or rigid) rows
    w_trans: FloatArray  # (m, 1, 1) 1 / sigma of the rigid translation rows (edge's units)
    W: Any  # every world's similarity (R (W, 3, 3), s (W,), Jw (W, 3, 3))
    L: Any  # the solve's layout (world rotation columns: L.rot)
    wk: dict[str, int]  # per camera: its world at the reference instant
    meas: dict[str, tuple[FloatArray, FloatArray]]  # per camera: measured (R, t), (n, ...)
    Jd: dict[str, FloatArray]  # per camera with a reference pose unknown: right Jacobian

    def put(
        self, block: FloatArray, cols: list[int] | None = None, at: np.ndarray | None = None
    ) -> None:
        """``block`` ``(m', 3, len(cols))`` in the current 3-row-a-frame block at frames ``at``
        (default all); ``cols`` default the edge's own unknowns."""

    def cam_block(
        self, c: str, y: FloatArray, sign: float, with_t: bool, weight: FloatArray
    ) -> None:
        """Derivatives of ``sign * (R_X y + [s R_X t + t_X])`` by camera ``c``'s world's
        similarity, whitened by ``weight`` ``(m, 3, 3)``."""

    def delta_block(self, c: str, i: int, D: FloatArray, first: int, last: int) -> None:
        """``D`` ``(3, last - first)`` by ``c``'s reference pose unknowns, at edge row ``i``."""

    def by_world(self, c: str) -> list[tuple[np.ndarray, int]]:
        """The edge's frames of ``c`` grouped by world: (positions, world)."""

    def next_block(self) -> None:
        """Move on to the next kind's 3 rows a frame."""


@dataclass(frozen=True)
class UrdfJoint:
    """One URDF ``<joint>``: its name, type, parent and child links, ``origin`` ``(4, 4)``
    (the child frame in the parent's) and axis ``(3,)`` (None: none written)."""

    name: str
    type: str
    parent: str
    child: str
    origin: FloatArray
    axis: FloatArray | None = None
    #: a revolute joint's ``(lower, upper)`` (rad); None: ``[-pi, pi]``
    limit: tuple[float, float] | None = None


class JointModel(ABC):
    """One joint type: everything the engine needs to know about it.

    Attributes
    ----------
    name : str
        The type's name in configs and artifacts (``type: ball``).
    n_params : int
        Its unknowns in the rig solve (:meth:`geometry` says what they are).
    residual_kinds : tuple of str
        Its residual blocks in order, 3 rows a frame each: ``pos`` (a point), ``rot`` (an
        axis, or a constant rotation) and ``trans`` (a constant translation).
    outlier_dim : int
        Dimension of one frame's residual for the outlier test (its rows less the
        directions a constraint cannot have: an axis difference has 2).
    noise_levels : int
        Noise levels fitted per edge (variance components).
    rotation_dof : float
        Degrees of freedom of one frame's ``rot`` block, for its noise level.
    has_point, has_axis, constant_transform : bool
        Its outputs: ``position_in`` (and priors, fixed-joint sessions, a joint
        trajectory), ``axis_in``, a constant ``T_q_p``.
    point_tells_rotation_noise : bool
        Its point rows estimate the cameras' rotation noise (a hinge's axis rows do better).
    pair_start : bool
        The rig's starting similarities across it come from the pairwise self-calibration
        of a ball joint (:func:`acs_cli.core.rig_start.ball_similarity`), which gives its
        point too; otherwise from the linear lifted solution.
    single_axis_ok : bool
        Its articulation may turn about one axis only (a hinge): not a degeneracy.
    articulation_dof, bundle_params : int
        The rig bundle's unknowns per frame and fixed ones (:mod:`acs_cli.core.rig_bundle`).
    """

    name: str
    n_params: int
    residual_kinds: tuple[str, ...]
    outlier_dim: int
    noise_levels: int
    rotation_dof: float = 3.0
    has_point: bool = False
    has_axis: bool = False
    constant_transform: bool = False
    point_tells_rotation_noise: bool = False
    pair_start: bool = False
    single_axis_ok: bool = False
    articulation_dof: int = 0
    bundle_params: int = 0

    # ------------------------------------------------------------------ rig solve

    @abstractmethod
    def geometry(self, e: FloatArray, anchor: Any) -> Geometry:
        """``(o_p, o_q, u_p, u_q)`` (see the module doc) from the unknowns ``e``
        ``(n_params,)`` and the fixed ``anchor`` of :meth:`start`; what is reported."""

    def residual_geometry(self, e: FloatArray, anchor: Any) -> Geometry:
        """:meth:`geometry` as the constraints use it (by default the same)."""
        return self.geometry(e, anchor)

    @abstractmethod
    def start(
        self,
        Rp: FloatArray,
        tp: FloatArray,
        Rq: FloatArray,
        tq: FloatArray,
        point: tuple[FloatArray, FloatArray] | None,
    ) -> tuple[FloatArray, Any]:
        """The starting unknowns ``(n_params,)`` and the fixed anchor (a linearisation
        point kept through the solve, or None) from the poses ``(m, 3, 3)``, ``(m, 3)`` of
        both cameras in one world (reference units); ``point``: ``(o_p, o_q)`` from the
        pairwise start (:attr:`pair_start`), if any."""

    @abstractmethod
    def residual_blocks(
        self,
        e: FloatArray,
        anchor: Any,
        Rp: FloatArray,
        tp: FloatArray,
        Rq: FloatArray,
        tq: FloatArray,
    ) -> dict[str, FloatArray]:
        """Raw (unwhitened) residuals ``(m, 3)`` by kind (:attr:`residual_kinds`, in that
        order) for both cameras' poses ``G`` in one world over the edge's frames."""

    @abstractmethod
    def jacobian(self, jc: EdgeJacobian) -> None:
        """Put the derivatives of the whitened :meth:`residual_blocks` into ``jc`` (one
        :meth:`EdgeJacobian.next_block` after each kind)."""

    def transform(self, e: FloatArray, anchor: Any) -> FloatArray | None:
        """``T_q_p`` ``(4, 4)`` when it is constant (:attr:`constant_transform`), else None."""
        return None

    def seed_point(self, e: FloatArray, side: int, position: FloatArray) -> None:
        """Put a prior's point ``(3,)`` in ``p`` (``side`` 0) or ``q`` (1) into the starting
        unknowns ``e`` (a view), where they hold it directly; by default it does not."""
        return None

    def fixed_joint_prior(
        self, joint: Edge, camera: str, T_w_c: FloatArray, label: str
    ) -> dict[str, dict[str, Any]]:
        """The parts of an :class:`~acs_cli.core.rig_solve.EdgePrior` (``position_in``,
        ``covariance_in``, ``line_in``, ``axis_in``) from a motion of ``camera`` about the
        joint held still (the paper's Algorithm II), ``T_w_c`` ``(n, 4, 4)`` in metres."""
        raise InputError(f"{label}: joint {joint.name} is {self.name}: nothing to hold still")

    # ------------------------------------------------------------------ degeneracy

    def misfit(
        self, joint: Edge, blocks: dict[str, FloatArray], mask: np.ndarray
    ) -> tuple[float, str] | None:
        """``(rms_deg, text)`` when the motion could contradict the type (its ``rot`` rows
        over the inlier ``mask``), or None: a type with no such check."""
        return None

    def planar_offset(
        self,
        joint: Edge,
        Rp: FloatArray,
        Rq: FloatArray,
        geometry: Callable[[], Geometry],
        axis: FloatArray,
        cos: float,
    ) -> str:
        """The offset a planar motion hides on the edge, in words, or ``""``: camera ``p``
        (rotations ``Rp`` ``(m, 3, 3)`` in the reference world) turns about the world
        ``axis`` only; ``cos`` is the cosine within which two axes are the same."""
        return ""

    def motion_advice(self, joint: Edge, Rst: FloatArray) -> list[str]:
        """Words on the joint's relative rotations ``R_p^T R_q`` ``(m, 3, 3)`` when its part
        of the rig is not determined (e.g. a ball that bends about one axis only)."""
        return []

    def position_hint_camera(self, joint: Edge) -> str | None:
        """The camera whose ``position_in`` to give in the config when the motion does not
        determine the joint, or None (a type without a point)."""
        return None

    # ------------------------------------------------------------------ outputs

    def urdf(
        self,
        joint: Edge,
        parent: str,
        child: str,
        T_parent_child: FloatArray,
        axis: FloatArray | None,
    ) -> tuple[list[str], list[UrdfJoint], str]:
        """The URDF of ``joint``'s articulation from body ``parent`` to body ``child`` (links),
        whose frame is ``T_parent_child`` ``(4, 4)`` (its origin at the joint's point) and
        ``axis`` ``(3,)`` the joint's axis in ``child`` (for a type with one): the extra
        links it needs, its joints, and a comment."""
        raise NotImplementedError(f"a {self.name} joint has no URDF articulation")

    # ------------------------------------------------------------------ rig bundle

    def bundle_start(
        self,
        position_in: list[FloatArray],
        axis_p: FloatArray | None,
        T_q_p: FloatArray,
        T_p_q: FloatArray,
        k: int,
    ) -> tuple[FloatArray | None, dict[str, FloatArray], FloatArray, FloatArray]:
        """The rig bundle's start from the pose-based estimate (its points ``position_in``
        in ``p`` and ``q``, none for a type without, and axis in ``p``): ``R0`` (a fixed rotation or
        ``(n, 3, 3)`` of them, or None), the fixed ``geom0``, the fixed unknowns
        ``(bundle_params,)`` and the articulation ``(n, articulation_dof)``; ``T_p_q``
        ``(n, 4, 4)`` at the bundle's frames, ``k`` the reference instant's row."""
        raise NotImplementedError(self.name)

    def bundle_edge(
        self, e: FloatArray, a: FloatArray, R0: Any, geom0: dict[str, FloatArray]
    ) -> tuple[FloatArray, FloatArray]:
        """``T_p_q`` at every frame, rotations ``(n, 3, 3)`` and translations ``(n, 3)``, from
        the fixed unknowns ``e`` and the articulations ``a`` ``(n, articulation_dof)``."""
        raise NotImplementedError(self.name)

    def bundle_geometry(self, e: FloatArray, R0: Any, geom0: dict[str, FloatArray]) -> FloatArray:
        """The reported geometry ``(o_p, o_q[, u_p, u_q])`` concatenated, from ``e``."""
        raise NotImplementedError(self.name)


def geometry_jacobian(
    model: JointModel, e: FloatArray, anchor: Any, for_residuals: bool = False
) -> FloatArray:
    """``(12, k)``: derivatives of ``(o_p, o_q, u_p, u_q)`` by the edge's ``k`` unknowns.

    Central differences of :meth:`JointModel.geometry` (a few vector operations, no frames).
    """
    size = e.size
    h = 1e-7
    E = np.eye(size) * h
    geom = model.residual_geometry if for_residuals else model.geometry

    def g(dx: FloatArray) -> FloatArray:
        parts = geom(e + dx, anchor)
        return np.concatenate([v if v is not None else np.zeros(3) for v in parts])

    return np.stack([(g(E[i]) - g(-E[i])) / (2 * h) for i in range(size)], axis=1)


def point_jacobian(jc: EdgeJacobian, o_p: FloatArray, o_q: FloatArray, Dg: FloatArray) -> None:
    """The point rows' derivatives (:func:`point_residual`) with ``Dg`` ``(12, k)``
    (:func:`geometry_jacobian`); ends the block."""
    p, q = jc.p, jc.q
    Wp = jc.whiten_pos * jc.mask
    yp = se3.rotate(jc.Rp, o_p) + jc.sp_tp
    yq = se3.rotate(jc.Rq, o_q) + jc.sq_tq
    jc.cam_block(p, yp, 1.0, True, Wp)
    jc.cam_block(q, yq, -1.0, True, Wp)
    # joint unknowns: R_Gp do_p - R_Gq do_q
    Be = np.matmul(jc.RGp, Dg[0:3]) - np.matmul(jc.RGq, Dg[3:6])
    jc.put(np.matmul(Wp, Be))
    if jc.kk.size:
        i = int(jc.kk[0])
        for c, o, sign in ((p, o_p, 1.0), (q, o_q, -1.0)):
            RX, sc = jc.W.R[jc.wk[c]], jc.W.s[jc.wk[c]]
            Dr = -sign * RX @ jc.meas[c][0][jc.k] @ se3.skew(o) @ jc.Jd[c] if c in jc.Jd else None
            if Dr is not None:
                jc.delta_block(c, i, Wp[i] @ np.concatenate([Dr, sign * sc * RX], 1), 0, 6)
    jc.next_block()
