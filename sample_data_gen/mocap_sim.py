"""Simulated motion capture of a leg: pelvis, femur and tibia tracked in one lab world.

Two functional trials, as a gait lab records them: a hip trial (the thigh swung about the
hip in flexion, abduction and rotation while the pelvis hardly moves) and a knee trial (the
knee flexed while the thigh moves). The hip is a ball joint, the knee a hinge. Each
segment's pose is measured with noise, independent per frame or correlated over time and
with the joint angles (skin markers that slide with the motion).

Lengths in metres; every pose is ``T_lab_segment``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from acs_cli.core import se3
from acs_cli.core.se3 import FloatArray

#: The truth: the hip centre in the pelvis and femur frames, the knee axis and point in the
#: femur and tibia frames (the knee point is the axis point nearest the femur's origin).
HIP_IN_PELVIS = np.array([0.08, -0.07, -0.09])
HIP_IN_FEMUR = np.array([0.01, 0.02, 0.21])
KNEE_AXIS_IN_FEMUR = np.array([1.0, 0.05, 0.02]) / np.linalg.norm([1.0, 0.05, 0.02])
KNEE_IN_FEMUR = np.array([0.0, 0.01, -0.19])
KNEE_IN_TIBIA = np.array([0.01, -0.01, 0.17])


@dataclass(frozen=True)
class MocapTrial:
    """One trial: each segment's measured ``T_lab_segment`` ``(n, 4, 4)`` and its truth."""

    times: FloatArray
    measured: dict[str, FloatArray]
    truth: dict[str, FloatArray] = field(default_factory=dict)


def _smooth(rng: np.random.Generator, t: FloatArray, amp: float, k: int = 3) -> FloatArray:
    """A smooth random signal ``(n,)`` of RMS about ``amp``: a few sines of random phase."""
    f = rng.uniform(0.15, 0.8, k)
    ph = rng.uniform(0, 2 * np.pi, k)
    return amp * np.sqrt(2.0 / k) * np.sum(np.sin(2 * np.pi * f * t[:, None] + ph), axis=1)


def _knee_frame() -> tuple[FloatArray, FloatArray]:
    """The knee axis in the tibia, and the tibia's rotation in the femur at zero flexion."""
    R0 = se3.matrix_from_rotvec(np.array([0.05, -0.03, 0.1]))
    return R0.T @ KNEE_AXIS_IN_FEMUR, R0


def _noisy(
    rng: np.random.Generator,
    T: FloatArray,
    sigma_rot_deg: float,
    sigma_trans: float,
    slide: FloatArray | None = None,
) -> FloatArray:
    """``T`` with independent noise, plus a correlated error (``slide``: ``(n, 6)``, rotation
    vector (rad) and translation (m) in the segment's frame) when given."""
    n = T.shape[0]
    d = np.concatenate(
        [
            np.radians(sigma_rot_deg) * rng.standard_normal((n, 3)),
            sigma_trans * rng.standard_normal((n, 3)),
        ],
        axis=1,
    )
    if slide is not None:
        d = d + slide
    E = se3.transforms_from_rt(se3.matrix_from_rotvec(d[:, :3]), d[:, 3:])
    return np.asarray(np.matmul(T, E))


def _slide(rng: np.random.Generator, angle: FloatArray, rot_deg: float, trans: float) -> FloatArray:
    """A skin-marker error ``(n, 6)`` that follows a joint angle (rad): smooth in the motion."""
    a = (angle - angle.mean()) / max(float(np.std(angle)), 1e-9)
    gains = rng.standard_normal(6)
    gains[:3] *= np.radians(rot_deg) / np.sqrt(3)
    gains[3:] *= trans / np.sqrt(3)
    return np.asarray(a[:, None] * gains[None, :] + 0.3 * a[:, None] ** 2 * gains[None, ::-1])


def _trial(
    rng: np.random.Generator,
    t: FloatArray,
    parent: tuple[str, FloatArray],
    child: tuple[str, FloatArray],
    angle: FloatArray,
    sigma_rot_deg: float,
    sigma_trans: float,
    slide_mm: float,
) -> MocapTrial:
    """Both segments measured with noise; the child's skin-marker error (``slide_mm``)
    follows the joint ``angle``."""
    slide = _slide(rng, angle, slide_mm / 5.0, slide_mm / 1000.0) if slide_mm else None
    return MocapTrial(
        t,
        {
            parent[0]: _noisy(rng, parent[1], sigma_rot_deg, sigma_trans),
            child[0]: _noisy(rng, child[1], sigma_rot_deg, sigma_trans, slide),
        },
        {parent[0]: parent[1], child[0]: child[1]},
    )


def hip_trial(
    rng: np.random.Generator,
    n: int = 300,
    rate: float = 60.0,
    sigma_rot_deg: float = 0.5,
    sigma_trans: float = 0.001,
    pelvis_turn_deg: float = 2.0,
    slide_mm: float = 0.0,
) -> MocapTrial:
    """The hip trial: pelvis and femur in one lab world; the femur swings about the hip
    (flexion +-35 deg, abduction and rotation +-15 deg) while the pelvis turns by about
    ``pelvis_turn_deg``. ``slide_mm`` adds a skin-marker error that follows the flexion."""
    t = np.arange(n) / rate
    rv = np.stack([_smooth(rng, t, np.radians(pelvis_turn_deg)) for _ in range(3)], axis=1)
    pos = np.stack([_smooth(rng, t, 0.02) for _ in range(3)], axis=1) + np.array([0.0, 0.0, 0.95])
    T_pel = se3.transforms_from_rt(se3.matrix_from_rotvec(rv), pos)
    flex = _smooth(rng, t, np.radians(25.0))
    hip = np.stack([flex, _smooth(rng, t, np.radians(10.0)), _smooth(rng, t, np.radians(8.0))], 1)
    R_pf = se3.matrix_from_rotvec(hip)
    t_pf = HIP_IN_PELVIS - np.einsum("nij,j->ni", R_pf, HIP_IN_FEMUR)
    T_fem = np.matmul(T_pel, se3.transforms_from_rt(R_pf, t_pf))
    return _trial(rng, t, ("pelvis", T_pel), ("femur", T_fem), flex, sigma_rot_deg,
                  sigma_trans, slide_mm)  # fmt: skip


def knee_trial(
    rng: np.random.Generator,
    n: int = 300,
    rate: float = 60.0,
    sigma_rot_deg: float = 0.5,
    sigma_trans: float = 0.001,
    slide_mm: float = 0.0,
) -> MocapTrial:
    """The knee trial: femur and tibia in one lab world; the knee flexes 5-95 deg (a hinge)
    while the thigh moves by +-20 deg."""
    t = np.arange(n) / rate
    rv = np.stack([_smooth(rng, t, np.radians(15.0)) for _ in range(3)], axis=1)
    pos = np.stack([_smooth(rng, t, 0.05) for _ in range(3)], axis=1) + np.array([0.1, 0.0, 0.7])
    T_fem = se3.transforms_from_rt(se3.matrix_from_rotvec(rv), pos)
    theta = np.radians(50.0) + _smooth(rng, t, np.radians(30.0))
    _, R0 = _knee_frame()
    R_ft = np.matmul(se3.matrix_from_rotvec(theta[:, None] * KNEE_AXIS_IN_FEMUR), R0)
    t_ft = KNEE_IN_FEMUR - np.einsum("nij,j->ni", R_ft, KNEE_IN_TIBIA)
    T_tib = np.matmul(T_fem, se3.transforms_from_rt(R_ft, t_ft))
    return _trial(rng, t, ("femur", T_fem), ("tibia", T_tib), theta, sigma_rot_deg,
                  sigma_trans, slide_mm)  # fmt: skip


def knee_axis_in_tibia() -> FloatArray:
    """The knee axis ``(3,)`` in the tibia's frame (the truth)."""
    return _knee_frame()[0]
