"""Synthetic articulated camera systems and their trajectories (the paper's section 5).

A two-camera rig: camera A and camera B on two bodies joined at a joint O. The joint is at
``o_a`` in A's frame and ``o_b`` in B's frame (both constant). An articulation is a rotation
``Q`` about the joint, expressed in A's frame, so that for a point ``p_b`` of B's frame

    p_a = o_a + Q @ R0 @ (p_b - o_b)

i.e. ``T_a_b(Q) = [Q R0, o_a - Q R0 o_b]``. A hinge restricts ``Q`` to rotations about one
axis. Sequences are written as ``T_world_cam`` stacks (``(n, 4, 4)``), as in TUM files.

Noise model: each pose ``T_world_cam = [R, t]`` becomes ``[R Exp(n_r), t + n_t]`` with
``n_r ~ N(0, sigma_rot^2 I)`` (radians, per axis, body frame) and ``n_t ~ N(0, sigma_trans^2 I)``
(metres). Unknown scale: translations in the written file are ``mu * (t + n_t)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from acs_cli.core import se3

FloatArray = se3.FloatArray


def random_unit_vectors(rng: np.random.Generator, n: int) -> FloatArray:
    """``(n, 3)`` directions uniform on the sphere."""
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def random_rotations(rng: np.random.Generator, n: int, max_angle_deg: float = 180.0) -> FloatArray:
    """``(n, 3, 3)`` rotations about uniform axes with angles uniform in ``[0, max_angle_deg]``."""
    angles = np.radians(rng.uniform(0.0, max_angle_deg, size=n))
    return se3.matrix_from_rotvec(random_unit_vectors(rng, n) * angles[:, None])


def random_transform(rng: np.random.Generator, translation_scale: float = 5.0) -> FloatArray:
    """One random rigid transform ``(4, 4)``: any rotation, translation in a cube."""
    R = random_rotations(rng, 1)[0]
    t = rng.uniform(-translation_scale, translation_scale, size=3)
    return se3.transforms_from_rt(R, t)


@dataclass(frozen=True)
class SyntheticRig:
    """Ground truth of a two-camera ACS.

    Attributes
    ----------
    o_a, o_b : ndarray, shape (3,)
        The joint in camera A's and camera B's frame (metres).
    R0 : ndarray, shape (3, 3)
        Relative rotation ``R_a_b`` at zero articulation.
    hinge_axis_a : ndarray of shape (3,) or None
        Unit hinge axis in A's frame; ``None`` for a ball (3-DOF) joint.
    """

    o_a: FloatArray
    o_b: FloatArray
    R0: FloatArray
    hinge_axis_a: FloatArray | None = None

    def T_a_b(self, Q: FloatArray) -> FloatArray:
        """``(n, 4, 4)`` relative poses ``T_a_b`` for articulations ``Q`` ``(n, 3, 3)``."""
        R = Q @ self.R0
        t = self.o_a - np.einsum("nij,j->ni", R, self.o_b)
        return se3.transforms_from_rt(R, t)

    def articulations(self, rng: np.random.Generator, n: int, max_angle_deg: float) -> FloatArray:
        """``(n, 3, 3)`` random articulations: ball joint or hinge about ``hinge_axis_a``."""
        if self.hinge_axis_a is None:
            return random_rotations(rng, n, max_angle_deg)
        angles = np.radians(rng.uniform(-max_angle_deg, max_angle_deg, size=n))
        return se3.matrix_from_rotvec(angles[:, None] * self.hinge_axis_a)


def make_rig(
    rng: np.random.Generator,
    joint_range: tuple[float, float] = (1.0, 2.0),
    hinge: bool = False,
) -> SyntheticRig:
    """A random rig with ``|o_a|, |o_b|`` uniform in ``joint_range`` (metres), as in section 5."""
    dirs = random_unit_vectors(rng, 2)
    norms = rng.uniform(*joint_range, size=2)
    axis = random_unit_vectors(rng, 1)[0] if hinge else None
    return SyntheticRig(
        o_a=dirs[0] * norms[0],
        o_b=dirs[1] * norms[1],
        R0=random_rotations(rng, 1)[0],
        hinge_axis_a=axis,
    )


@dataclass(frozen=True)
class Sequence:
    """True trajectories of the two cameras of a rig (``T_world_cam``, metres).

    ``T_wa_a`` is expressed in world A, ``T_wb_b`` in world B; ``T_wb_wa`` maps world A
    to world B (the identity when both cameras see one shared world, as with overlap).
    ``joint_in_world_a`` is the joint's fixed world position for fixed-joint sequences.
    """

    kind: str
    T_wa_a: FloatArray
    T_wb_b: FloatArray
    T_wb_wa: FloatArray
    T_a_b: FloatArray
    joint_in_world_a: FloatArray | None = None
    timestamps: FloatArray = field(default_factory=lambda: np.zeros(0))

    @property
    def n(self) -> int:
        return int(self.T_wa_a.shape[0])

    def T_b_a(self, reference: int = 0) -> FloatArray:
        """True ``T_b_a`` at frame ``reference`` (the paper's ``H_BA``)."""
        return se3.invert_transforms(self.T_a_b[reference])


def _finish(
    kind: str,
    rng: np.random.Generator,
    T_w_a: FloatArray,
    T_a_b: FloatArray,
    shared_world: bool,
    joint_w: FloatArray | None = None,
    fps: float = 10.0,
) -> Sequence:
    T_w_b = T_w_a @ T_a_b
    T_wa_w = np.eye(4) if shared_world else random_transform(rng)
    T_wb_w = T_wa_w if shared_world else random_transform(rng)
    T_wb_wa = T_wb_w @ se3.invert_transforms(T_wa_w)
    n = T_w_a.shape[0]
    joint_wa = None if joint_w is None else se3.transform_points(T_wa_w, joint_w)
    return Sequence(
        kind=kind,
        T_wa_a=T_wa_w @ T_w_a,
        T_wb_b=T_wb_w @ T_w_b,
        T_wb_wa=T_wb_wa,
        T_a_b=T_a_b,
        joint_in_world_a=joint_wa,
        timestamps=np.arange(n) / fps,
    )


def general_sequence(
    rng: np.random.Generator,
    rig: SyntheticRig,
    n: int = 30,
    *,
    max_rotation_deg: float = 90.0,
    max_articulation_deg: float = 60.0,
    translation_range: float = 1.5,
    shared_world: bool = False,
) -> Sequence:
    """General motion: camera A moves freely, the joint articulates at random.

    With ``shared_world`` both trajectories are in one world (the overlap scenario of
    Algorithm I); otherwise each is in its own random world (Algorithms III and IV).
    """
    R = random_rotations(rng, n, max_rotation_deg)
    t = rng.uniform(-translation_range, translation_range, size=(n, 3))
    T_w_a = se3.transforms_from_rt(R, t)
    T_a_b = rig.T_a_b(rig.articulations(rng, n, max_articulation_deg))
    return _finish("overlap" if shared_world else "general", rng, T_w_a, T_a_b, shared_world)


def fixed_joint_sequence(
    rng: np.random.Generator,
    rig: SyntheticRig,
    n: int = 30,
    *,
    max_rotation_deg: float = 60.0,
    max_articulation_deg: float = 60.0,
) -> Sequence:
    """Fixed-joint motion (Algorithm II): the joint stays at one world point.

    Camera A rotates about the joint; the rig articulates, so B rotates about it too.
    Each trajectory is expressed in its own world.
    """
    joint_w = rng.uniform(-1.0, 1.0, size=3)
    R = random_rotations(rng, n, max_rotation_deg)
    t = joint_w - np.einsum("nij,j->ni", R, rig.o_a)
    T_w_a = se3.transforms_from_rt(R, t)
    T_a_b = rig.T_a_b(rig.articulations(rng, n, max_articulation_deg))
    return _finish("fixed_joint", rng, T_w_a, T_a_b, shared_world=False, joint_w=joint_w)


def add_pose_noise(
    rng: np.random.Generator,
    T_world_cam: FloatArray,
    sigma_rot_deg: float,
    sigma_trans: float,
) -> FloatArray:
    """Noisy copies of poses ``(n, 4, 4)``: ``[R Exp(n_r), t + n_t]`` (see module doc)."""
    n = T_world_cam.shape[0]
    dR = se3.matrix_from_rotvec(rng.normal(scale=np.radians(sigma_rot_deg), size=(n, 3)))
    out = T_world_cam.copy()
    out[:, :3, :3] = T_world_cam[:, :3, :3] @ dR
    out[:, :3, 3] += rng.normal(scale=sigma_trans, size=(n, 3))
    return out


def corrupt_poses(
    rng: np.random.Generator, T_world_cam: FloatArray, o: FloatArray, frames: np.ndarray
) -> FloatArray:
    """Gross outliers (a flipped board, a bad PnP) in copies of poses ``(n, 4, 4)``.

    Frames ``frames[0], frames[2], ...`` get a 30 degree rotation error about an axis across
    the lever arm ``o`` (the joint in the camera, so that it moves the joint); frames
    ``frames[1], frames[3], ...`` a 1 m translation error in a random direction.
    """
    out = T_world_cam.copy()
    for j, f in enumerate(frames):
        if j % 2 == 0:
            axis = np.cross(o, rng.normal(size=3))
            axis /= np.linalg.norm(axis)
            out[f, :3, :3] = out[f, :3, :3] @ se3.matrix_from_rotvec(np.radians(30.0) * axis)
        else:
            d = rng.normal(size=3)
            out[f, :3, 3] += d / np.linalg.norm(d)
    return out


def scale_translations(T_world_cam: FloatArray, mu: float) -> FloatArray:
    """Poses with translations multiplied by ``mu`` (a monocular SLAM's unknown scale)."""
    out = T_world_cam.copy()
    out[:, :3, 3] *= mu
    return out


def smooth_rotvecs(rng: np.random.Generator, t: FloatArray, amp_deg: float) -> FloatArray:
    """``(n, 3)`` rotation vectors: per axis a sum of three sinusoids (0.05-0.5 Hz)."""
    freq = rng.uniform(0.05, 0.5, size=(3, 3))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(3, 3))
    amp = np.radians(amp_deg) * rng.uniform(0.3, 1.0, size=(3, 3)) / 2.0
    return np.sum(amp * np.sin(2.0 * np.pi * freq * t[:, None, None] + phase), axis=2)


def smooth_positions(rng: np.random.Generator, t: FloatArray, extent: float) -> FloatArray:
    """``(n, 3)`` positions (metres): per axis two sinusoids (0.05-0.4 Hz) of ``extent / 2``."""
    freq = rng.uniform(0.05, 0.4, size=(3, 2))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(3, 2))
    return 0.5 * extent * np.sum(np.sin(2.0 * np.pi * freq * t[:, None, None] + phase), axis=2)


def smooth_general_sequence(
    rng: np.random.Generator,
    rig: SyntheticRig,
    n: int = 300,
    *,
    fps: float = 30.0,
    time_offset_s: float = 0.0,
    max_rotation_deg: float = 60.0,
    max_articulation_deg: float = 40.0,
    translation_range: float = 1.0,
) -> Sequence:
    """General motion that is smooth in time (sums of sinusoids), sampled at ``fps``.

    Camera B's clock runs ``time_offset_s`` ahead of A's: ``T_wb_b[i]`` is B's true pose at
    A's time ``timestamps[i] - time_offset_s`` although B stamps it ``timestamps[i]``; so
    A's pose stamped ``t`` pairs with B's stamped ``t + time_offset_s`` (the convention of
    :mod:`acs_cli.core.time_offset`). ``T_a_b`` holds the truth at A's times.
    """
    t = np.arange(n) / fps
    keys = (rng.integers(2**32), rng.integers(2**32), rng.integers(2**32))

    def motion(tt: FloatArray) -> tuple[FloatArray, FloatArray]:
        g = [np.random.default_rng(int(k)) for k in keys]
        R = se3.matrix_from_rotvec(smooth_rotvecs(g[0], tt, max_rotation_deg))
        pos = smooth_positions(g[1], tt, translation_range)
        Q = se3.matrix_from_rotvec(smooth_rotvecs(g[2], tt, max_articulation_deg))
        if rig.hinge_axis_a is not None:
            ang = np.linalg.norm(se3.rotvec_from_matrix(Q), axis=1)
            Q = se3.matrix_from_rotvec(ang[:, None] * rig.hinge_axis_a)
        T_w_a = se3.transforms_from_rt(R, pos)
        return T_w_a, rig.T_a_b(Q)

    T_w_a, T_a_b = motion(t)
    seq = _finish("general", rng, T_w_a, T_a_b, shared_world=False, fps=fps)
    if time_offset_s:
        T_w_a_b, T_a_b_b = motion(t - time_offset_s)  # B's samples, taken earlier
        T_wb_w = seq.T_wb_b[0] @ se3.invert_transforms(T_w_a[0] @ T_a_b[0])
        seq = replace(seq, T_wb_b=T_wb_w @ T_w_a_b @ T_a_b_b)
    return seq


def pluslib_stylus_recording(
    rng: np.random.Generator, frames: int = 100, outliers: int = 5
) -> tuple[FloatArray, np.ndarray, FloatArray]:
    """PlusLib's stylus test (vtkStylusCalibrationTest.cxx), in millimetres: a stylus
    turning about its 210 mm tip (``frames`` tracker poses, 0.1 deg / 0.25 mm noise), with
    ``outliers`` of them replaced by random poses (rotations about x, y, z uniform in +-160
    degrees, translations uniform in +-1000 mm).

    Returns
    -------
    T_world_cam : ndarray, shape (frames, 4, 4)
    bad : ndarray of int, shape (outliers,)
        The replaced frames.
    tip : ndarray, shape (3,)
        The tip in the stylus' frame (mm).
    """
    tip = random_unit_vectors(rng, 1)[0] * 210.0
    rig = SyntheticRig(o_a=tip, o_b=tip, R0=np.eye(3))
    T = fixed_joint_sequence(rng, rig, frames, max_rotation_deg=40.0).T_wa_a
    T = add_pose_noise(rng, T, 0.1, 0.25)
    bad = rng.choice(frames, size=outliers, replace=False)
    angles = np.radians(rng.uniform(-160.0, 160.0, size=(outliers, 3)))
    rx, ry, rz = (se3.matrix_from_rotvec(np.eye(3)[j] * angles[:, j : j + 1]) for j in range(3))
    T[bad, :3, :3] = rx @ ry @ rz
    T[bad, :3, 3] = rng.uniform(-1000.0, 1000.0, size=(outliers, 3))
    return T, bad, tip


def hand_eye_pair(
    rng: np.random.Generator, n: int = 30, sigma_rot_deg: float = 0.2, sigma_trans: float = 0.002
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Two bodies on one rigid body, each in its own world (a camera on a robot's flange):
    noisy ``T_world_a``, ``T_world_b`` ``(n, 4, 4)`` and the true ``T_b_a``."""
    T_b_a = se3.transforms_from_rt(
        se3.matrix_from_rotvec(np.array([0.3, -0.5, 0.2])), np.array([0.05, 0.1, 0.12])
    )
    T_w_a = se3.transforms_from_rt(random_rotations(rng, n, 60.0), rng.uniform(-0.5, 0.5, (n, 3)))
    T_w_b = random_transform(rng) @ T_w_a @ se3.invert_transforms(T_b_a)
    return (
        add_pose_noise(rng, T_w_a, sigma_rot_deg, sigma_trans),
        add_pose_noise(rng, T_w_b, sigma_rot_deg, sigma_trans),
        T_b_a,
    )


@dataclass(frozen=True)
class NearHingePair:
    """Two cameras joined by a ball joint that bends mostly about one axis (a knee), each
    camera's poses in one world (``T_w_a``, ``T_w_b``: the overlap's) and B's also in a
    world of its own (``T_wb_b``: the relative pose's). See :func:`near_hinge_pair`."""

    T_w_a: FloatArray
    T_w_b: FloatArray
    T_wb_b: FloatArray
    timestamps: FloatArray
    axis_in_a: FloatArray  # the flexion axis in A's frame, at the articulation's rest pose
    axis_in_b: FloatArray  # ... and in B's (constant)
    o_a: FloatArray
    o_b: FloatArray


def near_hinge_pair(
    rng: np.random.Generator,
    n: int,
    *,
    flex_deg: float = 25.0,
    wobble_deg: float = 1.8,
    sigma_rot_deg: float = 0.05,
    sigma_trans: float = 0.0005,
    fps: float = 30.0,
) -> NearHingePair:
    """A ball joint bending ``flex_deg`` (RMS) about one axis ``u`` (three smooth cycles)
    and ``wobble_deg`` (RMS, at random) about each of the two axes across it, the joint 0.3 m
    from each camera; camera A turning about every axis (up to 90 deg) and moving within
    +-1 m. ``wobble_deg`` at about 7% of ``flex_deg`` is a near-hinge (rotation ratio about
    0.1), a ``wobble_deg`` near ``flex_deg`` a well-spread ball."""
    u = random_unit_vectors(rng, 1)[0]
    across = np.linalg.svd(u[None, :])[2][1:]  # (2, 3): orthonormal, across u
    phi = np.radians(flex_deg) * np.sqrt(2.0) * np.sin(np.linspace(0.0, 6.0 * np.pi, n) + 0.3)
    w = np.radians(wobble_deg) * rng.standard_normal((n, 2))
    R0 = random_rotations(rng, 1)[0]
    R_ab = R0 @ se3.matrix_from_rotvec(phi[:, None] * u + w @ across)
    o_a, o_b = random_unit_vectors(rng, 2) * 0.3
    T_a_b = se3.transforms_from_rt(R_ab, o_a - np.einsum("nij,j->ni", R_ab, o_b))
    T_w_a = se3.transforms_from_rt(random_rotations(rng, n, 90.0), rng.uniform(-1, 1, (n, 3)))
    T_w_b = T_w_a @ T_a_b
    X = random_transform(rng, 2.0)  # world B's pose in the shared world, inverted
    Ta = add_pose_noise(rng, T_w_a, sigma_rot_deg, sigma_trans)
    Tb = add_pose_noise(rng, T_w_b, sigma_rot_deg, sigma_trans)
    return NearHingePair(Ta, Tb, X @ Tb, np.arange(n) / fps, R0 @ u, u, o_a, o_b)
