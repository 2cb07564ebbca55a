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

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from acs_cli.core import se3
from acs_cli.core.rig import RigTopology, rig_topology
from acs_cli.core.rig_bundle import CameraViews
from acs_cli.core.rig_solve import CameraTrack, Recordings
from sample_data_gen.acs_sim import (
    add_pose_noise,
    random_rotations,
    random_transform,
    random_unit_vectors,
    smooth_positions,
    smooth_rotvecs,
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
    smooth: bool = False,
    time_offsets: dict[str, float] | None = None,
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
    smooth : bool
        Motion and articulations smooth in time (sums of sinusoids, sampled at ``fps``), as a
        video's; otherwise independent at random from frame to frame.
    time_offsets : dict of str to float, optional
        With ``smooth``: a camera's clock minus the reference camera's (seconds). Its poses
        are taken at ``t - offset`` and stamped ``t`` (``T_W_c`` keeps the truth at ``t``).
    """
    cams: list[str] = []
    for _, b, _t in joints:
        cams += [c for c in b if c not in cams]
    if reference in cams:
        cams.remove(reference)
    cams.insert(0, reference)
    topo = rig_topology(cams, joints, reference)
    edges = edges if edges is not None else make_edges(rng, joints)
    if smooth:
        return _smooth_recording(
            rng, n, topo, edges, unknown_scale, sigma_rot_deg, sigma_trans, max_rotation_deg,
            max_articulation_deg, translation_range, fps, time_offsets or {},
        )  # fmt: skip
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
    in_order = {c: T_W[c] for c in cams}  # the config's order (the draws' order)
    T_wc, mu = _trajectory_files(rng, in_order, unknown_scale, sigma_rot_deg, sigma_trans)
    return RigRecording(
        topology=topo,
        edges=edges,
        T_W_c=T_W,
        T_wc_c=T_wc,
        mu=mu,
        unknown_scale={c: c in unknown_scale for c in cams},
        timestamps=np.arange(n) / fps,
    )


def _trajectory_files(
    rng: np.random.Generator,
    T_W: dict[str, FloatArray],
    unknown_scale: tuple[str, ...],
    sigma_rot_deg: float,
    sigma_trans: float,
) -> tuple[dict[str, FloatArray], dict[str, float]]:
    """What each camera's trajectory file holds (its own world, noise, its own scale) and
    each camera's units per metre."""
    T_wc: dict[str, FloatArray] = {}
    mu: dict[str, float] = {}
    for c, T_true in T_W.items():
        T = random_transform(rng) @ T_true
        if sigma_rot_deg > 0 or sigma_trans > 0:
            T = add_pose_noise(rng, T, sigma_rot_deg, sigma_trans)
        mu[c] = float(rng.uniform(0.3, 3.0)) if c in unknown_scale else 1.0
        T = T.copy()
        T[:, :3, 3] *= mu[c]
        T_wc[c] = T
    return T_wc, mu


def _smooth_recording(
    rng: np.random.Generator,
    n: int,
    topo: RigTopology,
    edges: dict[str, EdgeTruth],
    unknown_scale: tuple[str, ...],
    sigma_rot_deg: float,
    sigma_trans: float,
    max_rotation_deg: float,
    max_articulation_deg: float,
    translation_range: float,
    fps: float,
    offsets: dict[str, float],
) -> RigRecording:
    """:func:`rig_recording` with ``smooth``: each camera sampled on its own clock."""
    keys = rng.integers(2**32, size=3 + len(edges))
    t = np.arange(n) / fps

    def chain(tt: FloatArray) -> dict[str, FloatArray]:
        g = [np.random.default_rng(int(k)) for k in keys]
        R = se3.matrix_from_rotvec(smooth_rotvecs(g[0], tt, max_rotation_deg))
        pos = smooth_positions(g[1], tt, translation_range)
        T_W = {topo.reference: se3.transforms_from_rt(R, pos)}
        for i, step in enumerate(topo.tree_order()):
            e = edges[step.joint.name]
            w = smooth_rotvecs(g[3 + i], tt, max_articulation_deg)
            if e.type == "rigid":
                w = np.zeros_like(w)
            elif e.type == "hinge" and e.axis_p is not None:
                w = w[:, :1] * e.axis_p
            T_p_q = e.T_p_q(se3.matrix_from_rotvec(w))
            T_W[step.target] = T_W[step.source] @ (
                T_p_q if step.forward else se3.invert_transforms(T_p_q)
            )
        return T_W

    T_W = chain(t)
    # each camera sampled on its own clock
    sampled = {c: chain(t - offsets[c])[c] if offsets.get(c) else T_W[c] for c in topo.cameras}
    T_wc, mu = _trajectory_files(rng, sampled, unknown_scale, sigma_rot_deg, sigma_trans)
    return RigRecording(
        topology=topo,
        edges=edges,
        T_W_c=T_W,
        T_wc_c=T_wc,
        mu=mu,
        unknown_scale={c: c in unknown_scale for c in topo.cameras},
        timestamps=t,
    )


@dataclass(frozen=True)
class CornerRecording:
    """A rig whose cameras each see their own checkerboard: corners, PnP poses and truth.

    Attributes
    ----------
    rig : RigRecording
        The truth (``T_W_c``; ``T_wc_c`` is not used).
    board_points : ndarray, shape (m, 3)
        The board's corners in its frame (metres), the same board for every camera.
    corners : dict of ndarray (n, m, 2)
        Detected corners (pixels, with noise) of each camera.
    valid : dict of ndarray of bool (n, m)
        Frames where the camera sees its whole board, facing it (all corners or none).
    intrinsics, intrinsics0 : dict of ndarray (9,)
        True and initial ``fx fy cx cy k1 k2 p1 p2 k3``.
    T_board_cam : dict of ndarray (n, 4, 4)
        PnP poses with the initial intrinsics (identity where not ``valid``).
    """

    rig: RigRecording
    board_points: FloatArray
    corners: dict[str, FloatArray]
    valid: dict[str, np.ndarray]
    intrinsics: dict[str, FloatArray]
    intrinsics0: dict[str, FloatArray]
    T_board_cam: dict[str, FloatArray]

    @property
    def common(self) -> np.ndarray:
        """Frames where every camera sees its board."""
        return np.all([v.all(axis=1) for v in self.valid.values()], axis=0)

    def tracks(self) -> dict[str, CameraTrack]:
        """The PnP poses as the rig solve's tracks (metric)."""
        return {c: CameraTrack(T, self.valid[c].all(axis=1)) for c, T in self.T_board_cam.items()}

    def views(self, corners: dict[str, FloatArray] | None = None) -> dict[str, CameraViews]:
        """The corners (or ``corners`` instead) as the rig bundle's views, with the initial
        intrinsics."""
        got = self.corners if corners is None else corners
        return {
            c: CameraViews(got[c], self.valid[c], self.board_points, self.intrinsics0[c])
            for c in self.rig.topology.cameras
        }

    def two_trials(
        self, first: str, second: str
    ) -> tuple[dict[str, CameraTrack], dict[str, CameraViews], Recordings, np.ndarray, int]:
        """The recording as two trials, its halves: ``second`` (a camera) not recorded in
        the first, ``first`` not in the second. Returns the tracks and views, the
        ``Recordings`` (``hip``, ``knee``; separate worlds), the instants where every camera
        its trial recorded sees its board, and the first of them in the first trial (a
        reference instant)."""
        n = next(iter(self.valid.values())).shape[0]
        of = np.repeat([0, 1], [n // 2, n - n // 2])
        absent = {second: of == 0, first: of == 1}
        none = np.zeros(n, bool)
        tracks = {
            c: CameraTrack(t.T_w_c, t.valid & ~absent.get(c, none), t.unknown_scale)
            for c, t in self.tracks().items()
        }
        views = {
            c: dataclasses.replace(v, valid=v.valid & ~absent.get(c, none)[:, None])
            for c, v in self.views().items()
        }
        common = np.ones(n, bool)
        for c in self.rig.topology.cameras:
            common &= views[c].valid.any(axis=1) | absent.get(c, none)
        ref = int(np.flatnonzero(common & (of == 0))[0])
        return tracks, views, Recordings(("hip", "knee"), of, (False, False)), common, ref


def rig_corner_recording(
    rng: np.random.Generator,
    n: int = 150,
    *,
    joints: tuple[tuple[str, tuple[str, str], str], ...] = SAMPLE_JOINTS,
    noise_px: float = 0.2,
    intrinsics_error: float = 0.003,
    board_distance: float = 2.0,
    reference: str = "cam0",
) -> CornerRecording:
    """Simulate a rig of board cameras: each camera's board stands ``board_distance`` in
    front of its mean pose, facing it; frames where the board is behind, seen at more than
    55 deg or far outside a 640x480 image are not observed. The initial intrinsics are off
    by ``intrinsics_error`` in focal length (and 1 px in the centre, 5% in distortion), and
    the PnP poses use them, as a calibration from separate sessions would.
    """
    import cv2

    rec = rig_recording(
        rng,
        n,
        joints=joints,
        reference=reference,
        edges=make_edges(rng, joints, joint_range=(0.4, 0.8)),
        max_rotation_deg=35.0,
        max_articulation_deg=35.0,
        translation_range=0.3,
    )
    gx, gy = np.meshgrid(np.arange(9), np.arange(6))
    board = np.stack([gx.ravel() * 0.15, gy.ravel() * 0.15, np.zeros(gx.size)], axis=1)
    board[:, :2] -= board[:, :2].mean(axis=0)
    corners, valid, intr, intr0, poses = {}, {}, {}, {}, {}
    for c in rec.topology.cameras:
        f = 600.0 + 20.0 * rng.normal()
        K = np.array([[f, 0.0, 320.0], [0.0, 1.001 * f, 240.0], [0.0, 0.0, 1.0]])
        dist = np.array([-0.2, 0.08, 1e-3, -1e-3, 0.0])
        T_W_c = rec.T_W_c[c]
        U, _, Vt = np.linalg.svd(T_W_c[:, :3, :3].sum(axis=0))  # the mean orientation
        Rm = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
        T_W_b = se3.transforms_from_rt(Rm, T_W_c[:, :3, 3].mean(axis=0) + board_distance * Rm[:, 2])
        T_c_b = np.matmul(se3.invert_transforms(T_W_c), T_W_b)
        depth = np.einsum("nj,mj->nm", T_c_b[:, 2, :3], board) + T_c_b[:, None, 2, 3]
        px = np.stack(
            [
                cv2.projectPoints(board, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K, dist)[0][:, 0]
                for T in T_c_b
            ]
        )
        px += rng.normal(scale=noise_px, size=px.shape)
        seen = (
            (depth > 0.3).all(axis=1)
            & (np.abs(T_c_b[:, 2, 2]) > np.cos(np.radians(55.0)))
            & (np.abs(px[..., 0] - 320.0) < 600.0).all(axis=1)
            & (np.abs(px[..., 1] - 240.0) < 500.0).all(axis=1)
        )
        K0 = K.copy()
        K0[0, 0] *= 1.0 + intrinsics_error
        K0[1, 1] *= 1.0 + intrinsics_error
        K0[0, 2] += 1.0
        K0[1, 2] -= 1.0
        d0 = 0.95 * dist
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        for i in np.flatnonzero(seen):
            _ok, rv, tv = cv2.solvePnP(board, px[i], K0, d0)
            T[i] = se3.invert_transforms(se3.transforms_from_rt(cv2.Rodrigues(rv)[0], tv.ravel()))
        corners[c] = px
        valid[c] = np.broadcast_to(seen[:, None], px.shape[:2]).copy()
        intr[c] = np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], *dist])
        intr0[c] = np.array([K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2], *d0])
        poses[c] = T
    return CornerRecording(rec, board, corners, valid, intr, intr0, poses)


def fixed_joint_motion(
    rng: np.random.Generator, o: FloatArray, axis: FloatArray | None = None, n: int = 40
) -> FloatArray:
    """A fixed-joint session of one camera: ``T_world_cam`` ``(n, 4, 4)`` (metres) of a
    camera turning about a world-fixed joint at ``o`` (in the camera's frame): about every
    axis (up to 60 deg) for a ball, about ``axis`` (camera frame, +-50 deg) for a hinge;
    0.2 deg / 2 mm pose noise, in a random world."""
    if axis is None:
        R = random_rotations(rng, n, 60.0)
    else:
        ang = np.radians(rng.uniform(-50, 50, n))
        R = se3.matrix_from_rotvec(ang[:, None] * axis)  # R_w_c with the world = camera 0
    p_w = rng.uniform(-1, 1, 3)
    T = se3.transforms_from_rt(R, p_w - np.einsum("nij,j->ni", R, o))
    return add_pose_noise(rng, random_transform(rng) @ T, 0.2, 0.002)
