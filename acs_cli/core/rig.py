"""The rig: cameras are nodes, joints are the edges of a tree.

An articulated camera system of many cameras is a kinematic tree. Each camera sits on a
rigid body; an edge joins two cameras and has a type:

- ``ball``: a spherical joint (the paper's model). Fixed at ``position_in[p]`` in camera
  ``p``'s frame and at ``position_in[q]`` in camera ``q``'s, whatever the articulation.
- ``hinge``: a revolute joint. An axis fixed in both bodies (``axis_in[p]``, ``axis_in[q]``,
  unit vectors) and a point on it, the same physical point in both cameras. The point is
  the one on the axis nearest camera ``p``'s optical centre (``p`` the edge's first camera),
  unless the rig config chooses another (:func:`hinge_point_from_nearest`).
- ``rigid``: both cameras on one body; ``T_q_p`` is constant.

The pose between any two cameras at one instant chains along the tree's unique path, as in
pytransform3d's ``TransformManager``: ``T_c_a = T_c_b @ T_b_a``. An edge ``between: [p, q]``
stores ``T_q_p`` (maps points of ``p``'s frame into ``q``'s); walking it from ``q`` to ``p``
uses its inverse.

This module is topology and chaining only (no estimation): :class:`RigTopology` validates
a tree (every error names the offending key) and answers paths (:meth:`RigTopology.tree_order`
walks it from the reference camera, each step forward along its edge's ``T_q_p`` or back);
and the conventions a rig config chooses for a hinge's outputs (:func:`oriented_axis`,
:func:`hinge_point_from_nearest`).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from acs_cli.core.joints import JOINT_MODELS, joint_types
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError

#: The joint types an edge can have: the registry's (:mod:`acs_cli.core.joints`).
JOINT_TYPES = joint_types()


@dataclass(frozen=True)
class RigJoint:
    """One edge of the rig's tree.

    Attributes
    ----------
    name : str
        The joint's key in the config (``joints.<name>``).
    between : tuple of str
        ``(p, q)``: the two cameras it joins. Quantities of the edge are expressed in
        ``p``'s and ``q``'s frames; its transform is ``T_q_p``.
    type : str
        A registered joint type (:data:`acs_cli.core.joints.JOINT_MODELS`: ball, hinge,
        rigid).
    """

    name: str
    between: tuple[str, str]
    type: str

    def other(self, camera: str) -> str:
        """The camera at the other end of the edge from ``camera``."""
        p, q = self.between
        if camera == p:
            return q
        if camera == q:
            return p
        raise ValueError(f"camera {camera!r} is not on joint {self.name!r}")


@dataclass(frozen=True)
class PathStep:
    """One step of a path through the tree: along ``joint`` from ``source`` to ``target``.

    ``forward`` is True when the step goes from the edge's first camera to its second
    (so that it applies the edge's ``T_q_p``), False when it applies the inverse.
    """

    joint: RigJoint
    source: str
    target: str

    @property
    def forward(self) -> bool:
        return self.joint.between == (self.source, self.target)


@dataclass(frozen=True)
class RigTopology:
    """A validated tree of cameras and joints with a reference camera.

    Build it with :func:`rig_topology`, which checks it. ``cameras`` keeps the config's
    order; ``joints`` too.
    """

    cameras: tuple[str, ...]
    joints: tuple[RigJoint, ...]
    reference: str

    def joint(self, name: str) -> RigJoint:
        """The joint called ``name``."""
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(name)

    def edges_of(self, camera: str) -> list[RigJoint]:
        """The joints that touch ``camera``, in config order."""
        return [j for j in self.joints if camera in j.between]

    def tree_order(self) -> list[PathStep]:
        """Breadth-first steps from the reference camera: each camera (but the reference)
        appears once as a ``target``, after its parent."""
        steps: list[PathStep] = []
        seen = {self.reference}
        queue = deque([self.reference])
        while queue:
            c = queue.popleft()
            for j in self.edges_of(c):
                d = j.other(c)
                if d not in seen:
                    seen.add(d)
                    steps.append(PathStep(j, c, d))
                    queue.append(d)
        return steps

    def parents(self) -> dict[str, PathStep]:
        """For every camera but the reference, the step that reaches it from its parent."""
        return {s.target: s for s in self.tree_order()}

    def path(self, source: str, target: str) -> list[PathStep]:
        """The steps from ``source`` to ``target`` along the tree's unique path."""
        for name in (source, target):
            if name not in self.cameras:
                raise ValueError(f"unknown camera {name!r}; the rig has {', '.join(self.cameras)}")
        parents = self.parents()

        def to_root(c: str) -> list[str]:
            out = [c]
            while out[-1] != self.reference:
                out.append(parents[out[-1]].source)
            return out

        up, down = to_root(source), to_root(target)
        common = next(c for c in up if c in down)
        steps: list[PathStep] = []
        for c in up[: up.index(common)]:
            s = parents[c]
            steps.append(PathStep(s.joint, c, s.source))
        for c in reversed(down[: down.index(common)]):
            steps.append(parents[c])
        return steps


def rig_topology(
    cameras: Iterable[str],
    joints: Iterable[tuple[str, Iterable[str], str]],
    reference: str,
    *,
    key: str = "joints",
) -> RigTopology:
    """Check and build a rig's tree.

    Parameters
    ----------
    cameras : iterable of str
        Camera names, in order.
    joints : iterable of (name, between, type)
        The edges; ``between`` names two cameras.
    reference : str
        The reference camera.
    key : str
        The config key the joints come from, for messages (``joints.<name>.between``).

    Raises
    ------
    InputError
        Naming the key: an unknown joint type, a joint not between two distinct known
        cameras, two joints between the same pair, a cycle, a camera in no joint (or a
        rig in several pieces), an unknown reference camera.
    """
    cams = tuple(str(c) for c in cameras)
    if not cams:
        raise InputError("a rig needs at least one camera (cameras)")
    if len(set(cams)) != len(cams):
        raise InputError("cameras: a camera name is given twice")
    if reference not in cams:
        raise InputError(
            f"reference.camera: {reference!r} is not one of the cameras ({', '.join(cams)})"
        )
    edges: list[RigJoint] = []
    pairs: dict[frozenset[str], str] = {}
    # union-find over cameras: an edge joining two already-connected cameras closes a cycle
    root = {c: c for c in cams}

    def find(c: str) -> str:
        while root[c] != c:
            root[c] = root[root[c]]
            c = root[c]
        return c

    for name, between, jtype in joints:
        name = str(name)
        b = tuple(str(c) for c in between)
        where = f"{key}.{name}"
        if jtype not in JOINT_MODELS:
            raise InputError(
                f"{where}.type: {jtype!r} is not a joint type; choose one of "
                + ", ".join(JOINT_MODELS)
            )
        if len(b) != 2:
            raise InputError(f"{where}.between: needs two cameras, got {len(b)}")
        for c in b:
            if c not in cams:
                raise InputError(
                    f"{where}.between: unknown camera {c!r}; the cameras are {', '.join(cams)}"
                )
        if b[0] == b[1]:
            raise InputError(f"{where}.between: joins camera {b[0]!r} to itself")
        pair = frozenset(b)
        if pair in pairs:
            raise InputError(
                f"{where}.between: {b[0]} and {b[1]} are already joined by {key}.{pairs[pair]}; "
                "two cameras have at most one joint between them"
            )
        pairs[pair] = name
        ra, rb = find(b[0]), find(b[1])
        if ra == rb:
            raise InputError(
                f"{where}.between: joining {b[0]} and {b[1]} closes a cycle (they are already "
                "connected through other joints); a rig's joints must form a tree"
            )
        root[ra] = rb
        edges.append(RigJoint(name, (b[0], b[1]), str(jtype)))
    if len(cams) > 1:
        used = {c for e in edges for c in e.between}
        lonely = [c for c in cams if c not in used]
        if lonely:
            raise InputError(
                f"cameras.{lonely[0]}: the camera is in no joint; join it to the rig "
                f"({key}.<name>: {{between: [{lonely[0]}, <camera>], type: ...}}) or remove it"
            )
        groups = {find(c) for c in cams}
        if len(groups) > 1:
            raise InputError(
                f"{key}: the rig falls into {len(groups)} separate pieces; join them with a joint"
            )
    return RigTopology(cams, tuple(edges), reference)


def oriented_axis(
    axis_in: Mapping[str, FloatArray], body: str, direction: FloatArray
) -> tuple[dict[str, FloatArray], float]:
    """A hinge's axis in each body's frame, its sign chosen to point along ``direction``.

    Parameters
    ----------
    axis_in : mapping of str to ndarray, shape (3,)
        The unit axis in each of the joint's two bodies' frames (one line, one sign).
    body : str
        The body whose frame ``direction`` is in (one of ``axis_in``'s).
    direction : ndarray, shape (3,)
        Where the user wants the axis to point (any length).

    Returns
    -------
    axis_in : dict of str to ndarray, shape (3,)
        Both flipped when the axis makes an obtuse angle with ``direction``.
    angle_deg : float
        The angle between the axis so chosen and ``direction`` (0 to 90 deg): near 90, the
        direction barely tells the sign.
    """
    u = np.asarray(axis_in[body], dtype=float)
    d = np.asarray(direction, dtype=float)
    cos = float(u @ d) / max(float(np.linalg.norm(u) * np.linalg.norm(d)), 1e-300)
    sign = -1.0 if cos < 0 else 1.0
    out: dict[str, FloatArray] = {c: sign * np.asarray(v, dtype=float) for c, v in axis_in.items()}
    return out, float(np.degrees(np.arccos(min(abs(cos), 1.0))))


def hinge_point_from_nearest(
    geometry: FloatArray, covariance: FloatArray, side: int, nearest: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """A hinge's point moved along its axis to the one nearest a given point, in both
    bodies' frames, with its covariance.

    The axis is the line ``o_b + s u_b`` in body ``b``'s frame (``b`` the ``side`` the given
    point ``y`` is in); its point nearest ``y`` is at ``s = u_b . (y - o_b)``, and the same
    physical point is ``x_c = o_c + s u_c`` in either body ``c`` (``o_p``, ``o_q`` are one
    physical point, ``u_p``, ``u_q`` one direction). The covariance is first order over the
    whole geometry (its cross-covariances included): with ``d = y - o_b``,

    - ``dx_b = (I - u_b u_b^T) do_b + (u_b d^T + s I) du_b``;
    - ``dx_c = do_c + s du_c - u_c u_b^T do_b + u_c d^T du_b`` for the other body ``c``,

    so that a point far along the axis has the axis's angular uncertainty times ``|s|``
    across it. The axes' sign does not matter (``-u`` with its cross-covariances' signs
    turned gives the same point and covariance).

    Parameters
    ----------
    geometry : ndarray, shape (12,)
        ``(o_p, o_q, u_p, u_q)`` concatenated: a point of the axis in ``p``'s and ``q``'s
        frames (the same physical point; reference units) and the unit axis in each (the
        same direction).
    covariance : ndarray, shape (12, 12)
        Covariance of ``geometry`` (reference units squared; the axes' rows unitless).
    side : {0, 1}
        Which body's frame ``nearest`` is in: ``p`` (0) or ``q`` (1).
    nearest : ndarray, shape (3,)
        The given point in that body's frame (reference units).

    Returns
    -------
    points : ndarray, shape (2, 3)
        The axis point nearest ``nearest``, in ``p``'s frame then ``q``'s (reference units).
    covariance : ndarray, shape (6, 6)
        Covariance of ``points`` flattened (``x_p`` then ``x_q``).
    """
    g = np.asarray(geometry, dtype=float)
    C = np.asarray(covariance, dtype=float)
    if g.shape != (12,) or C.shape != (12, 12) or side not in (0, 1):
        raise ValueError("a hinge's geometry is (12,) with a (12, 12) covariance, side 0 or 1")
    o = (g[0:3], g[3:6])
    u = (g[6:9], g[9:12])
    d = np.asarray(nearest, dtype=float) - o[side]
    s = float(u[side] @ d)
    points = np.stack([o[0] + s * u[0], o[1] + s * u[1]])
    # J = d(x_p, x_q) / d(o_p, o_q, u_p, u_q): the move s along each body's axis, then s's
    # own derivatives (ds = -u_b^T do_b + d^T du_b) carried along each axis
    J = np.zeros((6, 12))
    eye = np.eye(3)
    for c in (0, 1):
        J[3 * c : 3 * c + 3, 3 * c : 3 * c + 3] = eye
        J[3 * c : 3 * c + 3, 6 + 3 * c : 9 + 3 * c] = s * eye
        J[3 * c : 3 * c + 3, 3 * side : 3 * side + 3] -= np.outer(u[c], u[side])
        J[3 * c : 3 * c + 3, 6 + 3 * side : 9 + 3 * side] += np.outer(u[c], d)
    return points, J @ C @ J.T
