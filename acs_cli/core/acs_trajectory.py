"""The trajectory of an articulated camera system in one frame, and joint-constraint residuals.

After calibration (the joint ``o_a``, ``o_b`` and the relative pose ``T_b_a`` at a reference
instant ``k``) the two cameras' trajectories, each in its own world, can be put in one
frame: camera A's optical frame at the reference instant, written ``r`` below. With the
paper's motions relative to the reference, ``H_A^i = inv(T_wa_a[k]) T_wa_a[i]`` (the same
for B), and ``T_r_b[k] = inv(T_b_a)``:

    T_r_a[i] = inv(T_wa_a[k]) @ T_wa_a[i]
    T_r_b[i] = inv(T_b_a) @ inv(T_wb_b[k]) @ T_wb_b[i]

and the joint, seen from each camera, at

    j_a[i] = T_r_a[i] @ o_a        j_b[i] = T_r_b[i] @ o_b.

A perfect calibration of noiseless poses gives ``j_a[i] = j_b[i]`` for every ``i``; the
distance ``|j_a[i] - j_b[i]|`` is the per-frame consistency of the joint constraint.

Unknown scale (Algorithm IV): A's translations are in "A units" (``mu_a`` x metres), B's and
``T_b_a``'s translation and ``o_b`` in "B units" (``mu_b`` x metres), ``phi_ba = mu_b / mu_a``.
Everything is brought to A units by dividing B's lengths by ``phi_ba``.

Every function is pure and vectorised over frames (numpy only). Conventions are those of
``docs/conventions.md``: ``T_a_b`` maps points of frame ``b`` into frame ``a``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from acs_cli.core import se3
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError

__all__ = [
    "AcsTrajectory",
    "fixed_joint_residuals",
    "joint_path",
    "overlap_relative_pose",
    "overlap_residuals",
    "recover_trajectory",
    "scale_translations",
]


@dataclass(frozen=True, eq=False)
class AcsTrajectory:
    """The ACS's trajectory in camera A's frame at the reference instant (frame ``r``).

    Attributes
    ----------
    T_r_a : ndarray, shape (n, 4, 4)
        Camera A's pose at each paired frame (``T_r_a[reference]`` is the identity).
        Translations in A's units.
    T_r_b : ndarray, shape (n, 4, 4)
        Camera B's pose (``T_r_b[reference] = inv(T_b_a)``, translation divided by
        ``phi_ba``). Translations in A's units.
    joint_from_a, joint_from_b : ndarray, shape (n, 3)
        The joint's position as camera A (``T_r_a[i] o_a``) and as camera B
        (``T_r_b[i] o_b / phi_ba``) see it, A's units.
    consistency : ndarray, shape (n,)
        ``|joint_from_a - joint_from_b|`` per frame, A's units.
    reference : int
        Index of the reference instant among the ``n`` frames.
    phi_ba : float
        The relative scale ``mu_b / mu_a`` that B's lengths were divided by (1 for known
        scale).
    """

    T_r_a: FloatArray
    T_r_b: FloatArray
    joint_from_a: FloatArray
    joint_from_b: FloatArray
    consistency: FloatArray
    reference: int
    phi_ba: float

    @property
    def n(self) -> int:
        """Number of frames."""
        return int(self.T_r_a.shape[0])

    @property
    def T_r_joint(self) -> FloatArray:
        """The joint's pose ``(n, 4, 4)``: camera A's orientation at ``joint_from_a``."""
        return se3.transforms_from_rt(self.T_r_a[:, :3, :3], self.joint_from_a).reshape(-1, 4, 4)


# ------------------------------------------------------------------------------ validators


def _transforms(T: ArrayLike, name: str) -> FloatArray:
    """A stack ``(n, 4, 4)`` of rigid transforms, ``n >= 1`` (raises naming the shape)."""
    arr = np.asarray(T, dtype=float)
    if arr.ndim != 3 or arr.shape[1:] != (4, 4) or arr.shape[0] == 0:
        raise InputError(f"{name} must have shape (n, 4, 4) with n >= 1, got {arr.shape}")
    return se3.check_transforms(arr, name=name)


def _transform(T: ArrayLike, name: str) -> FloatArray:
    """One rigid transform of shape ``(4, 4)``."""
    arr = np.asarray(T, dtype=float)
    if arr.shape != (4, 4):
        raise InputError(f"{name} must have shape (4, 4), got {arr.shape}")
    return se3.check_transforms(arr, name=name)[0]


def _point(p: ArrayLike, name: str) -> FloatArray:
    """One 3-vector of shape ``(3,)``."""
    arr = np.asarray(p, dtype=float)
    if arr.shape != (3,):
        raise InputError(f"{name} must have shape (3,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    return arr


def _reference(reference: int, n: int) -> int:
    k = int(reference)
    if not 0 <= k < n:
        raise InputError(f"reference must be an index in [0, {n}), got {reference}")
    return k


def _positive(value: float, name: str) -> float:
    v = float(value)
    if not (np.isfinite(v) and v > 0.0):
        raise InputError(f"{name} must be a positive finite number, got {value!r}")
    return v


# ------------------------------------------------------------------------------ building blocks


def scale_translations(T: ArrayLike, factor: float) -> FloatArray:
    """Rigid transforms with their translations multiplied by ``factor``.

    Parameters
    ----------
    T : array_like, shape (n, 4, 4) or (4, 4)
        Rigid transforms.
    factor : float
        Positive; e.g. ``1 / phi_ba`` to bring B's units to A's.

    Returns
    -------
    ndarray, same shape as ``T``
    """
    out = np.array(T, dtype=float)
    out[..., :3, 3] *= _positive(factor, "factor")
    return out


def joint_path(T_w_c: ArrayLike, position_in_c: ArrayLike) -> FloatArray:
    """The joint's positions ``T_w_c[i] @ o_c`` in the trajectory's world.

    Parameters
    ----------
    T_w_c : array_like, shape (n, 4, 4)
        Camera poses in the world.
    position_in_c : array_like, shape (3,)
        The joint in the camera's frame (same length unit as the translations).

    Returns
    -------
    ndarray, shape (n, 3)
    """
    T = _transforms(T_w_c, "T_w_c")
    o = _point(position_in_c, "position_in_c")
    return np.asarray(T[:, :3, :3] @ o + T[:, :3, 3])


def overlap_relative_pose(T_w_a: ArrayLike, T_w_b: ArrayLike, reference: int = 0) -> FloatArray:
    """``T_b_a`` at the reference instant when both trajectories share one world (overlap).

    Parameters
    ----------
    T_w_a, T_w_b : array_like, shape (n, 4, 4)
        Paired poses of cameras A and B in one world.
    reference : int

    Returns
    -------
    ndarray, shape (4, 4)
        ``inv(T_w_b[k]) @ T_w_a[k]``.
    """
    Ta = _transforms(T_w_a, "T_w_a")
    Tb = _transforms(T_w_b, "T_w_b")
    if Ta.shape != Tb.shape:
        raise InputError(
            f"T_w_a {Ta.shape} and T_w_b {Tb.shape} must have the same shape (n, 4, 4)"
        )
    k = _reference(reference, Ta.shape[0])
    return np.asarray(se3.invert_transforms(Tb[k]) @ Ta[k])


# ------------------------------------------------------------------------------ recovery


def recover_trajectory(
    T_wa_a: ArrayLike,
    T_wb_b: ArrayLike,
    T_b_a: ArrayLike,
    position_in_a: ArrayLike,
    position_in_b: ArrayLike,
    reference: int = 0,
    phi_ba: float = 1.0,
) -> AcsTrajectory:
    """Both cameras' poses and the joint's path in camera A's frame at the reference instant.

    Parameters
    ----------
    T_wa_a : array_like, shape (n, 4, 4)
        Camera A's poses in its world (A units).
    T_wb_b : array_like, shape (n, 4, 4)
        Camera B's poses in its world (B units), paired with A's one to one.
    T_b_a : array_like, shape (4, 4)
        The relative pose at the reference instant: maps points of camera A's frame into
        camera B's (the paper's ``H_BA``); translation in B units.
    position_in_a : array_like, shape (3,)
        The joint in camera A's frame (A units; the paper's ``O_A``).
    position_in_b : array_like, shape (3,)
        The joint in camera B's frame (B units; ``O_B``).
    reference : int
        Index ``k`` of the reference instant among the ``n`` paired frames.
    phi_ba : float
        ``mu_b / mu_a``: B units per A unit (1 under known scale).

    Returns
    -------
    AcsTrajectory
        Poses and joint positions in A units, in frame ``r`` = camera A at frame ``k``.

    Raises
    ------
    ValueError
        (an :class:`~acs_cli.errors.InputError`) for wrong shapes (naming them), non-rigid
        transforms, a reference out of range or a non-positive ``phi_ba``.
    """
    Ta = _transforms(T_wa_a, "T_wa_a")
    Tb = _transforms(T_wb_b, "T_wb_b")
    if Ta.shape != Tb.shape:
        raise InputError(
            f"T_wa_a {Ta.shape} and T_wb_b {Tb.shape} must pair one to one: shape (n, 4, 4) each"
        )
    Tba = _transform(T_b_a, "T_b_a")
    o_a = _point(position_in_a, "position_in_a")
    o_b = _point(position_in_b, "position_in_b")
    k = _reference(reference, Ta.shape[0])
    phi = _positive(phi_ba, "phi_ba")

    to_a = 1.0 / phi  # B units -> A units
    Tb_a_units = scale_translations(Tb, to_a)
    T_r_b0 = scale_translations(se3.invert_transforms(Tba), to_a)
    T_r_a = np.matmul(se3.invert_transforms(Ta[k]), Ta)
    T_r_b = np.matmul(T_r_b0 @ se3.invert_transforms(Tb_a_units[k]), Tb_a_units)
    T_r_a[k] = np.eye(4)  # exactly, not to rounding
    T_r_b[k] = T_r_b0
    j_a = T_r_a[:, :3, :3] @ o_a + T_r_a[:, :3, 3]
    j_b = T_r_b[:, :3, :3] @ (o_b * to_a) + T_r_b[:, :3, 3]
    return AcsTrajectory(
        T_r_a=np.asarray(T_r_a),
        T_r_b=np.asarray(T_r_b),
        joint_from_a=np.asarray(j_a),
        joint_from_b=np.asarray(j_b),
        consistency=np.asarray(np.linalg.norm(j_a - j_b, axis=1)),
        reference=k,
        phi_ba=phi,
    )


# ------------------------------------------------------------------------------ residuals


def fixed_joint_residuals(
    T_w_c: ArrayLike, position_in_c: ArrayLike, joint_in_world: ArrayLike
) -> FloatArray:
    """Per-frame residual of the fixed-joint constraint (Algorithm II).

    Parameters
    ----------
    T_w_c : array_like, shape (n, 4, 4)
        One camera's poses in its world.
    position_in_c : array_like, shape (3,)
        The joint in that camera's frame.
    joint_in_world : array_like, shape (3,)
        The joint's (fixed) position in that world.

    Returns
    -------
    ndarray, shape (n,)
        ``|T_w_c[i] @ o_c - joint_in_world|``, in the trajectory's length unit.
    """
    j = joint_path(T_w_c, position_in_c)
    w = _point(joint_in_world, "joint_in_world")
    return np.asarray(np.linalg.norm(j - w, axis=1))


def overlap_residuals(
    T_w_a: ArrayLike, T_w_b: ArrayLike, position_in_a: ArrayLike, position_in_b: ArrayLike
) -> FloatArray:
    """Per-frame residual of the overlap constraint (Algorithm I): one joint, one world.

    Parameters
    ----------
    T_w_a, T_w_b : array_like, shape (n, 4, 4)
        Paired poses of cameras A and B in their shared world.
    position_in_a, position_in_b : array_like, shape (3,)
        The joint in each camera's frame.

    Returns
    -------
    ndarray, shape (n,)
        ``|T_w_a[i] @ o_a - T_w_b[i] @ o_b|``.
    """
    ja = joint_path(T_w_a, position_in_a)
    jb = joint_path(T_w_b, position_in_b)
    if ja.shape != jb.shape:
        raise InputError(
            f"T_w_a and T_w_b must pair one to one: shape (n, 4, 4) each, got n = "
            f"{ja.shape[0]} and {jb.shape[0]}"
        )
    return np.asarray(np.linalg.norm(ja - jb, axis=1))
