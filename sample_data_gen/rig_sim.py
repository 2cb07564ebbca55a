"""Synthetic rigs of many cameras: a kinematic tree of ball, hinge and rigid joints.

The truth is a tree of edges ``between: [p, q]``. Each edge has a rest transform and, for a
ball or a hinge, a joint point ``o_p`` (in ``p``'s frame) and ``o_q`` (in ``q``'s). An
articulation ``Q`` (a rotation about the joint, expressed in ``p``'s frame) gives

    T_p_q(Q) = [Q R0, o_p - Q R0 o_q]

as in :mod:`sample_data_gen.acs_sim`; a hinge restricts ``Q`` to rotations about its axis
``u_p`` (then ``u_q = R0^T u_p``), and ``o_p`` is the axis point nearest ``p``'s centre. A
rigid edge has ``Q = I``.

The reference camera moves freely in a physical world ``W``; the others follow along the
tree. Each camera's trajectory is then written in its own world (a random ``T_wc_W``) and,
for a camera with unknown scale, with its translations multiplied by ``mu_c``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from acs_cli.core import se3
from acs_cli.core.rig import RigTopology, rig_topology
from sample_data_gen.acs_sim import (
    add_pose_noise,
    random_rotations,
    random_transform,
    random_unit_vectors,
)

FloatArray = se3.FloatArray


@dataclass(frozen=True)
class EdgeTruth:
    """One edge's truth: ``R0`` (rest rotation ``R_p_q``), joint points, hinge axes."""

    name: str
    between: tuple[str, str]
    type: str
    R0: FloatArray
    o_p: FloatArray
    o_q: FloatArray
    axis_p: FloatArray | None = None

    @property
    def axis_q(self) -> FloatArray | None:
        return None if self.axis_p is None else self.R0.T @ self.axis_p

    def T_p_q(self, Q: FloatArray) -> FloatArray:
        """``(n, 4, 4)`` transforms ``T_p_q`` for articulations ``Q`` ``(n, 3, 3)``."""
        R = Q @ self.R0
        return se3.transforms_from_rt(R, self.o_p - np.einsum("nij,j->ni", R, self.o_q))

    def articulations(self, rng: np.random.Generator, n: int, max_deg: float) -> FloatArray:
        if self.type == "rigid":
            return np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
        if self.type == "hinge":
            assert self.axis_p is not None
            ang = np.radians(rng.uniform(-max_deg, max_deg, size=n))
            return se3.matrix_from_rotvec(ang[:, None] * self.axis_p)
        return random_rotations(rng, n, max_deg)


@dataclass(frozen=True)
class RigRecording:
    """A recording of a synthetic rig.

    Attributes
    ----------
    topology : RigTopology
    edges : dict of EdgeTruth
    T_W_c : dict of ndarray (n, 4, 4)
        True poses of every camera in the physical world (metres).
    T_wc_c : dict of ndarray (n, 4, 4)
        What each camera's trajectory file holds: its own world, its own scale, noise.
    mu : dict of float
        Each camera's trajectory units per metre (1 for a metric camera).
    timestamps : ndarray (n,)
    """

    topology: RigTopology
    edges: dict[str, EdgeTruth]
    T_W_c: dict[str, FloatArray]
    T_wc_c: dict[str, FloatArray]
    mu: dict[str, float]
    unknown_scale: dict[str, bool]
    timestamps: FloatArray = field(default_factory=lambda: np.zeros(0))

    def T_cam_ref(self, reference: int = 0) -> dict[str, FloatArray]:
        """True ``T_cam_ref`` (metres) of every camera at frame ``reference``."""
        ref = self.topology.reference
        T_ref = self.T_W_c[ref][reference]
        return {c: se3.invert_transforms(self.T_W_c[c][reference]) @ T_ref for c in self.T_W_c}

    def scale(self) -> dict[str, float]:
        """True scale of each camera: reference units per trajectory unit (``mu_ref / mu_c``)."""
        ref = self.topology.reference
        return {c: self.mu[ref] / self.mu[c] for c in self.mu}


#: The sample rig: a chain cam0 -(rigid)- cam1, cam0 -(ball)- cam2 -(hinge)- cam3 -(rigid)- cam4.
SAMPLE_JOINTS: tuple[tuple[str, tuple[str, str], str], ...] = (
    ("r01", ("cam0", "cam1"), "rigid"),
    ("j02", ("cam0", "cam2"), "ball"),
    ("j23", ("cam2", "cam3"), "hinge"),
    ("r34", ("cam3", "cam4"), "rigid"),
)


def make_edges(
    rng: np.random.Generator,
    joints: tuple[tuple[str, tuple[str, str], str], ...] = SAMPLE_JOINTS,
    joint_range: tuple[float, float] = (0.5, 1.5),
) -> dict[str, EdgeTruth]:
    """Random truth for each edge: joint points ``joint_range`` metres from each camera."""
    out = {}
    for name, (p, q), jtype in joints:
        dirs = random_unit_vectors(rng, 2)
        norms = rng.uniform(*joint_range, size=2)
        o_p, o_q = dirs[0] * norms[0], dirs[1] * norms[1]
        axis = None
        if jtype == "hinge":
            axis = random_unit_vectors(rng, 1)[0]
            # the hinge point is the axis point nearest p's centre
            o_p = o_p - (o_p @ axis) * axis
        out[name] = EdgeTruth(name, (p, q), jtype, random_rotations(rng, 1)[0], o_p, o_q, axis)
    return out


def rig_recording(
    rng: np.random.Generator,
    n: int = 100,
    *,
    joints: tuple[tuple[str, tuple[str, str], str], ...] = SAMPLE_JOINTS,
    reference: str = "cam0",
    unknown_scale: tuple[str, ...] = (),
    sigma_rot_deg: float = 0.0,
    sigma_trans: float = 0.0,
    max_rotation_deg: float = 90.0,
    max_articulation_deg: float = 45.0,
    translation_range: float = 1.5,
    planar: bool = False,
    edges: dict[str, EdgeTruth] | None = None,
    fps: float = 30.0,
) -> RigRecording:
    """Simulate a rig's general motion.

    Parameters
    ----------
    n : int
        Frames.
    unknown_scale : tuple of str
        Cameras whose trajectory has an unknown scale (``mu`` drawn in [0.3, 3]).
    sigma_rot_deg, sigma_trans : float
        Pose noise per axis (degrees, metres before scaling).
    planar : bool
        The reference body turns about its z axis only and moves in its x-y plane (a truck on
        flat ground); hinge axes then default to that z axis (pass ``edges`` to choose).
    """
    cams: list[str] = []
    for _, b, _t in joints:
        cams += [c for c in b if c not in cams]
    if reference in cams:
        cams.remove(reference)
    cams.insert(0, reference)
    topo = rig_topology(cams, joints, reference)
    edges = edges if edges is not None else make_edges(rng, joints)
    if planar:
        ang = np.radians(rng.uniform(-max_rotation_deg, max_rotation_deg, size=n))
        R = se3.matrix_from_rotvec(ang[:, None] * np.array([0.0, 0.0, 1.0]))
        t = rng.uniform(-translation_range, translation_range, size=(n, 3))
        t[:, 2] = 0.0
    else:
        R = random_rotations(rng, n, max_rotation_deg)
        t = rng.uniform(-translation_range, translation_range, size=(n, 3))
    T_W = {reference: se3.transforms_from_rt(R, t)}
    for step in topo.tree_order():
        e = edges[step.joint.name]
        T_p_q = e.T_p_q(e.articulations(rng, n, max_articulation_deg))
        T_W[step.target] = T_W[step.source] @ (
            T_p_q if step.forward else se3.invert_transforms(T_p_q)
        )
    T_wc: dict[str, FloatArray] = {}
    mu: dict[str, float] = {}
    for c in cams:
        T = random_transform(rng) @ T_W[c]
        if sigma_rot_deg > 0 or sigma_trans > 0:
            T = add_pose_noise(rng, T, sigma_rot_deg, sigma_trans)
        mu[c] = float(rng.uniform(0.3, 3.0)) if c in unknown_scale else 1.0
        T = T.copy()
        T[:, :3, 3] *= mu[c]
        T_wc[c] = T
    return RigRecording(
        topology=topo,
        edges=edges,
        T_W_c=T_W,
        T_wc_c=T_wc,
        mu=mu,
        unknown_scale={c: c in unknown_scale for c in cams},
        timestamps=np.arange(n) / fps,
    )
