"""Relative pose of non-overlapping cameras from the joint constraint (Algorithms III, IV).

Each camera's trajectory is known in its own world: ``T_wa_a[i]`` and ``T_wb_b[i]``. At
every instant the joint is one physical point, so its positions in the two worlds,

    j_a[i] = R_wa_i o_a + t_wa_i        j_b[i] = R_wb_i o_b + t_wb_i,

are related by one constant similarity ``X = T_wb_wa`` (rotation ``R_X``, translation
``t_X``, and scale ``phi_ba = mu_B / mu_A`` when each trajectory has its own unknown scale):

    j_b[i] = phi R_X j_a[i] + t_X.

The relative pose at the reference instant ``k`` follows as
``T_b_a = inv(T_wb_b[k]) X T_wa_a[k]`` (the paper's ``H_BA``).

The paper (eq. (24)) writes the same constraint with motions relative to the reference
frame, ``H_A^i = inv(T_wa_a[k]) T_wa_a[i]``, solves it linearly for ``R_BA`` (9 entries) and
``T_BA``, projects onto a rotation (with ``phi = trace(D) / 3`` under unknown scale, eq.
(43)) and refines roll, pitch, yaw, ``T_BA``, ``O_A`` (and ``phi``) by Levenberg-Marquardt
(eq. (25), (44)). That form takes the reference frame as exact. Ours treats every frame
alike, estimates the joint in both cameras together with ``X`` (priors from a fixed-joint
calibration when given), weights frames by their noise, and finally corrects the two
reference poses by the joint constraint before composing ``T_b_a``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from acs_cli.core import estimation, lsq, se3
from acs_cli.core.bundle import right_jacobians
from acs_cli.core.joint import (
    METHODS,
    MIN_ROTATION_SPREAD,
    lever_shapes,
)
from acs_cli.core.quality import JOINT_STD, OVERRIDE_HINT, largest_std, length_scale
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

#: Smallest ratio of the second to the first singular value of the centred joint
#: trajectory (in world A) for the rotation between the worlds to be observable.
COLLINEAR_RATIO = 0.02
#: Fewest paired frames for a relative pose from a known joint, and for self-calibration.
MIN_FRAMES = 5
MIN_FRAMES_SELF_CALIBRATION = 14
#: Camera A "turns about one axis only" when the weakest singular value of its stacked,
#: centred rotations is below this fraction of the strongest (about 3 degrees of wobble
#: per 60 degrees of turning). The paper's linear eq. (24) and self-calibration need more.
SINGLE_AXIS_RATIO = 0.05
#: A self-calibrated joint is "not determined" when its largest standard deviation exceeds
#: this fraction of its distance from the camera. Seen in simulation (30 frames, up to
#: 2.4 deg / 0.1 m pose noise): about 5% for general motion, 14-30% for a rigid or hinged
#: joint, whatever the noise level (the information along the free direction then comes
#: from the noise itself).
UNDETERMINED_STD_FRACTION = JOINT_STD.refuse


@dataclass(frozen=True)
class JointPrior:
    """A joint from an earlier calibration, used as a prior.

    Attributes
    ----------
    position_in_a, position_in_b : ndarray (3,) or None
    covariance_a, covariance_b : ndarray (3, 3) or None
        ``None`` means "exact" for the paper's method and a tight prior for ours.
    metric : bool
        True when the positions are in metres while the trajectories have unknown scales
        (``--joint-metric``): then ``mu_a`` and ``mu_b`` are estimated too.
    """

    position_in_a: FloatArray | None = None
    position_in_b: FloatArray | None = None
    covariance_a: FloatArray | None = None
    covariance_b: FloatArray | None = None
    metric: bool = False


@dataclass(frozen=True)
class RelposeEstimate:
    """Relative pose of camera B with respect to camera A at the reference instant.

    Attributes
    ----------
    T_b_a : ndarray, shape (4, 4)
        Maps points of camera A's frame into camera B's at the reference instant; its
        translation is in B's units (metres under known scale).
    covariance : ndarray, shape (6, 6)
        Of ``(rotation perturbation of R_b_a on the right (rad), t_b_a)``.
    reference : int
    phi_ba, phi_std : float
        Relative scale ``mu_B / mu_A`` (1 and 0 under known scale).
    mu_a, mu_b, mu_a_std, mu_b_std : float or None
        Absolute scales, when a metric joint was given under unknown scale.
    position_in_a, position_in_b : ndarray (3,)
        Joint in A's frame (A's units) and B's frame (B's units).
    covariance_a, covariance_b : ndarray (3, 3)
    T_wb_wa : ndarray, shape (4, 4)
        Rotation and translation of the similarity from world A to world B.
    residual_rms : float
        RMS of the joint-constraint residual (B's units) over the frames used.
    inliers : ndarray of bool, shape (n,)
    noise : dict
    method : str
    unknown_scale, self_calibrated : bool
    """

    T_b_a: FloatArray
    covariance: FloatArray
    reference: int
    phi_ba: float
    phi_std: float
    position_in_a: FloatArray
    position_in_b: FloatArray
    covariance_a: FloatArray
    covariance_b: FloatArray
    T_wb_wa: FloatArray
    residual_rms: float
    inliers: np.ndarray
    method: str
    unknown_scale: bool
    self_calibrated: bool
    mu_a: float | None = None
    mu_b: float | None = None
    mu_a_std: float | None = None
    mu_b_std: float | None = None
    noise: dict[str, float] = field(default_factory=dict)
    residuals: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))

    @property
    def T_a_b(self) -> FloatArray:
        """Pose of camera B in camera A's frame (the paper's tables' relative pose)."""
        return np.asarray(se3.invert_transforms(self.T_b_a))

    @property
    def rpy_deg(self) -> FloatArray:
        """Roll, pitch, yaw (deg) of ``R_a_b`` (the paper's ``~R_BA = R_BA^T``)."""
        return np.asarray(se3.rpy_deg_from_matrix(self.T_a_b[:3, :3]))

    @property
    def translation_b_in_a(self) -> FloatArray:
        """``t_a_b = -R_BA^T T_BA`` (the paper's ``~T_BA``), B's units."""
        return np.asarray(self.T_a_b[:3, 3])


# ----------------------------------------------------------------------------- helpers


def _kron_rows(v: FloatArray) -> FloatArray:
    """``K(v)`` ``(n, 3, 9)`` with ``K(v) vec(M) = M v`` for row-major ``vec(M)``."""
    n = v.shape[0]
    K = np.zeros((n, 3, 9))
    for r in range(3):  # three rows of a 3x3 matrix, not frames
        K[:, r, 3 * r : 3 * r + 3] = v
    return K


def _lstsq_scaled(A: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Least squares with column equilibration; returns the solution and singular values."""
    if A.shape[0] < 20 * A.shape[1]:
        scale = np.linalg.norm(A, axis=0)
        scale[scale == 0] = 1.0
        x, _, _, s = np.linalg.lstsq(A / scale, b, rcond=None)
        return x / scale, s
    # tall: the same least-squares problem through its (equilibrated) Gram matrix
    G = A.T @ A
    scale = np.sqrt(np.diag(G))
    scale[scale == 0] = 1.0
    Gs = G / np.outer(scale, scale)
    x = np.linalg.lstsq(Gs, (A.T @ b) / scale, rcond=None)[0]
    s = np.sqrt(np.maximum(np.linalg.eigvalsh(Gs)[::-1], 0.0))
    return x / scale, s


def similarity_from_points(
    P: FloatArray, Q: FloatArray, with_scale: bool
) -> tuple[FloatArray, FloatArray, float]:
    """Umeyama: ``R, t, s`` minimising ``sum |Q_i - (s R P_i + t)|^2`` for ``(n, 3)`` points."""
    mp, mq = P.mean(axis=0), Q.mean(axis=0)
    Pc, Qc = P - mp, Q - mq
    Sigma = Qc.T @ Pc / P.shape[0]
    U, D, Vt = np.linalg.svd(Sigma)
    S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ S @ Vt
    s = float(np.trace(np.diag(D) @ S) / np.mean(np.sum(Pc**2, axis=1))) if with_scale else 1.0
    return R, mq - s * R @ mp, s


def _check_inputs(
    T_wa_a: FloatArray, T_wb_b: FloatArray, reference: int
) -> tuple[FloatArray, FloatArray]:
    Ta, Tb = se3.check_paired_transforms(T_wa_a, T_wb_b, "relpose")
    n = Ta.shape[0]
    if not -n <= reference < n:
        raise InputError(
            f"reference frame {reference} is outside the {n} paired frames (0 to {n - 1}): "
            "give --reference (relpose.reference in a run config) within them"
        )
    return Ta, Tb


def _check_spread(j_a: FloatArray, what: str = "joint trajectory") -> None:
    c = j_a - j_a.mean(axis=0)
    s = np.linalg.svd(c, compute_uv=False)
    if s[0] <= 0 or s[1] / s[0] < COLLINEAR_RATIO:
        raise DegenerateMotionError(
            f"the {what} is (nearly) a straight line (singular value ratio "
            f"{(s[1] / s[0]) if s[0] > 0 else 0.0:.4f} < {COLLINEAR_RATIO}); the rotation about it "
            "is not determined. Move the rig along a curved path, turning and translating in "
            "different directions.",
            details={"singular_values": s.tolist()},
        )


def rpy_right_jacobian(rpy_rad: FloatArray) -> FloatArray:
    """``E`` ``(3, 3)`` with ``R(rpy + d) = R(rpy) Exp(E d + O(d^2))``.

    ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (:func:`se3.matrix_from_rpy_deg`, here in radians):
    a change of roll turns ``R`` about its own x axis, of pitch about ``Rx^T e_y``, of yaw
    about ``(Ry Rx)^T e_z`` (body frame). Singular at pitch = +-90 deg (gimbal lock).

    Parameters
    ----------
    rpy_rad : ndarray, shape (3,)
        Roll, pitch, yaw (radians).

    Returns
    -------
    ndarray, shape (3, 3)
        Columns: the body-frame rotation axes of roll, pitch and yaw.
    """
    roll, pitch, _yaw = np.asarray(rpy_rad, dtype=float)
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    # Rx^T e_y = (0, cr, -sr); (Ry Rx)^T e_z = Rx^T (-sp, 0, cp) = (-sp, sr cp, cr cp)
    return np.array([[1.0, 0.0, -sp], [0.0, cr, sr * cp], [0.0, -sr, cr * cp]])


# ----------------------------------------------------------------------------- paper


def _paper(
    Ta: FloatArray, Tb: FloatArray, o_a: FloatArray, reference: int, unknown_scale: bool
) -> tuple[FloatArray, FloatArray, FloatArray, float, FloatArray, FloatArray]:
    """Algorithms III / IV as published. Returns ``R_BA, T_BA, O_A, phi, residuals, cov``."""
    Ha = se3.invert_transforms(Ta[reference]) @ Ta  # H_A^i
    Hb = se3.invert_transforms(Tb[reference]) @ Tb  # H_B^i
    c = np.ascontiguousarray
    RA, TA, RB, TB = c(Ha[:, :3, :3]), c(Ha[:, :3, 3]), c(Hb[:, :3, :3]), c(Hb[:, :3, 3])
    RAf, RBf = RA.reshape(-1, 3), RB.reshape(-1, 3)
    n = Ta.shape[0]
    # eq. (24), linear in vec(R_BA) and T_BA:
    # [R_B^i K(O_A) - K(R_A^i O_A + T_A^i)] vec(R_BA) + (R_B^i - I) T_BA = -T_B^i
    KO = _kron_rows(np.broadcast_to(o_a, (n, 3)))
    A_rot = np.einsum("nij,njk->nik", RB, KO) - _kron_rows(np.einsum("nij,j->ni", RA, o_a) + TA)
    A = np.concatenate([A_rot, RB - np.eye(3)], axis=2).reshape(-1, 12)
    x, _ = _lstsq_scaled(A, -TB.reshape(-1))
    # eq. (38)-(43): R = U V^T, phi = trace(D) / 3
    R0, s = se3.project_to_rotation(x[:9].reshape(3, 3))
    phi0 = float(np.sum(s) / 3.0) if unknown_scale else 1.0
    rpy0 = np.radians(se3.rpy_deg_from_matrix(R0))

    def unpack(p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, float]:
        R = se3.matrix_from_rpy_deg(np.degrees(p[:3]))
        return R, p[3:6], p[6:9], (float(p[9]) if unknown_scale else 1.0)

    def res(p: FloatArray) -> FloatArray:
        # eq. (25) / (44)
        R, T, O, phi = unpack(p)
        ja = (RAf @ O).reshape(-1, 3) + TA
        r = phi * (RBf @ (R @ O)).reshape(-1, 3) + (RBf @ T).reshape(-1, 3) - T
        return np.asarray((r - phi * ja @ R.T + TB).reshape(-1))

    def jac(p: FloatArray) -> FloatArray:
        R, _T, O, phi = unpack(p)
        ja = (RAf @ O).reshape(-1, 3) + TA
        # d R / d rpy_k = R [e_k]x with e_k the columns of rpy_right_jacobian
        dR = np.matmul(R, se3.skew(rpy_right_jacobian(p[:3]).T))  # (3, 3, 3): k, i, j
        Jr = phi * (np.einsum("nij,kjl,l->nik", RB, dR, O) - np.einsum("nj,kij->nik", ja, dR))
        JT = RB - np.eye(3)
        JO = phi * ((RBf @ R).reshape(-1, 3, 3) - np.matmul(R, RA))
        blocks = [Jr, JT, JO]
        if unknown_scale:
            blocks.append(((RBf @ (R @ O)).reshape(-1, 3) - ja @ R.T)[:, :, None])
        return np.concatenate(blocks, axis=2).reshape(3 * n, -1)

    p0 = np.concatenate([rpy0, x[9:], o_a] + ([[phi0]] if unknown_scale else []))
    sol = lsq.solve(res, p0, jac=jac, method="lm")
    R, T, O, phi = unpack(sol.x)
    r = sol.fun.reshape(-1, 3)
    Jm = sol.jac
    dof = max(r.size - Jm.shape[1], 1)
    cov = float(np.sum(r**2) / dof) * np.linalg.pinv(Jm.T @ Jm)
    return R, T, O, phi, r, cov


# ----------------------------------------------------------------------------- ours


def _initial_lifted(
    Ta: FloatArray, Tb: FloatArray, o_a: FloatArray | None
) -> tuple[FloatArray, FloatArray, float, FloatArray, FloatArray]:
    """Linear initialisation of ``R_X, t_X, phi, o_a, o_b`` needing no joint.

    ``j_b = M j_a + t_X`` with ``M = phi R_X`` is bilinear in ``M`` and ``o_a``; lifting the
    products ``W[r, j, k] = M[r, j] o_a[k]`` to 27 unknowns makes it linear in
    ``(W, M, o_b, t_X)`` (42 unknowns, 3 equations a frame). With ``o_a`` known, ``M j_a`` is
    linear directly (15 unknowns).
    """
    n = Ta.shape[0]
    Ra, ta, Rb, tb = Ta[:, :3, :3], Ta[:, :3, 3], Tb[:, :3, :3], Tb[:, :3, 3]
    eye = np.broadcast_to(np.eye(3), (n, 3, 3))
    if o_a is None:
        AW = np.zeros((n, 3, 27))
        for r in range(3):  # the 3 rows of M, not frames
            AW[:, r, 9 * r : 9 * r + 9] = Ra.reshape(n, 9)
        A = np.concatenate([AW, _kron_rows(ta), -Rb, eye], axis=2).reshape(-1, 42)
        x, _ = _lstsq_scaled(A, tb.reshape(-1))
        W, M, o_b, t_X = x[:27].reshape(3, 3, 3), x[27:36].reshape(3, 3), x[36:39], x[39:42]
        o_a = np.einsum("rj,rjk->k", M, W) / float(np.sum(M * M))
    else:
        j_a = np.einsum("nij,j->ni", Ra, o_a) + ta
        A = np.concatenate([_kron_rows(j_a), -Rb, eye], axis=2).reshape(-1, 15)
        x, _ = _lstsq_scaled(A, tb.reshape(-1))
        M, o_b, t_X = x[:9].reshape(3, 3), x[9:12], x[12:15]
    R_X, s = se3.project_to_rotation(M)
    return R_X, t_X, float(np.mean(s)), np.asarray(o_a), o_b


def _self_calibration_starts(
    Ta: FloatArray, Tb: FloatArray, unknown_scale: bool, pack: Callable[..., FloatArray]
) -> list[FloatArray]:
    """Starting points of the self-calibration besides the lifted one: the linear solution
    with the joint at camera A's centre, and the same from B's side (A and B swapped, the
    similarity inverted)."""
    zero = np.zeros(3)
    R_X, t_X, phi, o_a, o_b = _initial_lifted(Ta, Tb, zero)
    starts = [pack(R_X, t_X, phi, o_a, o_b)]
    R_Y, t_Y, psi, o_b, o_a = _initial_lifted(Tb, Ta, zero)  # j_a = psi R_Y j_b + t_Y
    phi = 1.0 / max(psi, 1e-9) if unknown_scale else 1.0
    starts.append(pack(R_Y.T, -phi * R_Y.T @ t_Y, phi, o_a, o_b))
    return starts


#: Bound on the log of a scale factor inside the solver (phi within 1e-30..1e30).
_LOG_SCALE_BOUND = 69.0


class _Layout:
    """Index layout of the refined parameter vector."""

    def __init__(self, unknown_scale: bool, metric: bool):
        self.rot, self.t, self.oa, self.ob = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)
        k = 12
        self.logphi = k if unknown_scale else None
        k += int(unknown_scale)
        self.logmu = k if (unknown_scale and metric) else None
        k += int(unknown_scale and metric)
        self.size = k

    def scales(self, x: FloatArray) -> tuple[float, float]:
        """``phi`` and ``mu`` of ``x`` (1 where not estimated). The log scales are clipped
        far beyond any real ratio: a start that wanders off must not overflow (it then
        loses on likelihood)."""

        def exp(i: int | None) -> float:
            if i is None:
                return 1.0
            return float(np.exp(np.clip(x[i], -_LOG_SCALE_BOUND, _LOG_SCALE_BOUND)))

        return exp(self.logphi), exp(self.logmu)


def estimate_relpose(
    T_wa_a: FloatArray,
    T_wb_b: FloatArray,
    prior: JointPrior | None = None,
    *,
    unknown_scale: bool = False,
    reference: int = 0,
    method: str = "refined",
    reject_outliers: bool = True,
    accept_weak: bool = False,
) -> RelposeEstimate:
    """Relative pose (and scale) of two cameras joined by a joint, from general motion.

    Parameters
    ----------
    T_wa_a, T_wb_b : ndarray, shape (n, 4, 4)
        Paired poses ``T_world_cam`` of camera A and B, each in its own world.
    prior : JointPrior, optional
        The joint from a fixed-joint calibration. Without it (or with neither position)
        the joint is self-calibrated from this motion (ours only; the paper needs ``O_A``).
    unknown_scale : bool
        Each trajectory's translations carry an unknown factor (Algorithm IV).
    reference : int
        Frame index at which ``T_b_a`` is reported (negative counts from the end).
    method : {"refined", "paper"}
    reject_outliers : bool
    accept_weak : bool
        Return a self-calibrated joint a narrow motion hardly determines instead of refusing
        it (``--accept-weak``; the stage marks the result weak); a joint that hardly bends
        or bends about one axis is refused whatever it says.

    Returns
    -------
    RelposeEstimate

    Raises
    ------
    InputError
        Mismatched inputs, or ``method="paper"`` without ``prior.position_in_a``.
    DegenerateMotionError
        Too few frames or a motion that does not determine the answer.
    """
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    Ta, Tb = _check_inputs(T_wa_a, T_wb_b, reference)
    n = Ta.shape[0]
    reference = reference % n
    prior = prior or JointPrior()
    self_cal = prior.position_in_a is None and prior.position_in_b is None
    need = MIN_FRAMES_SELF_CALIBRATION if self_cal else MIN_FRAMES
    if n < need:
        raise DegenerateMotionError(
            f"{n} paired frames; {'self-calibration' if self_cal else 'a relative pose'} needs at "
            f"least {need} frames of general motion: record more, with the rig turning about "
            "several axes while it moves and bends"
        )
    if method == "paper" or self_cal:
        # eq. (24) and the self-calibration need camera A to turn about two axes or more
        notes = motion_diagnosis(Ta, Tb)
        if notes["camera"]:
            what = "the paper's Algorithm III/IV" if method == "paper" else "self-calibration"
            raise DegenerateMotionError(
                f"{what} cannot use this motion: {notes['camera']}. Record the rig turning "
                "about two or more axes"
                + (
                    ", or give the joint from a fixed-joint session (--joint)"
                    if self_cal
                    else ", or use the refined method, which handles it with a known joint"
                ),
                details={"diagnosis": notes},
            )
    if method == "paper":
        return _estimate_paper(Ta, Tb, prior, unknown_scale, reference)
    est = _estimate_refined(Ta, Tb, prior, unknown_scale, reference, self_cal, reject_outliers)
    _check_determined(est, Ta, Tb, accept_weak)
    return est


def motion_diagnosis(
    Ta: FloatArray, Tb: FloatArray, R_wb_wa: FloatArray | None = None
) -> dict[str, str]:
    """What a general motion lacks, in words: ``{"camera": ..., "joint": ...}`` ("" if fine).

    ``camera``: camera A hardly turns (pure translation) or turns about one axis only
    (planar motion). ``joint``: the joint hardly bends (a rigid pair) or bends about one
    axis only (a hinge); it needs the rotation from world A to world B, ``R_wb_wa``
    ``(3, 3)`` (identity for one world), and is left empty without it. Thresholds:
    :data:`MIN_ROTATION_SPREAD` (RMS, rad) and :data:`SINGLE_AXIS_RATIO`.
    """
    Ra = Ta[:, :3, :3]
    checks = [("camera", Ra)]
    if R_wb_wa is not None:
        # the articulation R_a_b = R_a_wa R_wa_wb R_wb_b
        checks.append(("joint", np.einsum("nji,jk,nkl->nil", Ra, R_wb_wa.T, Tb[:, :3, :3])))
    words = {
        "camera": ("camera A hardly turns (pure translation)",
                   "camera A turns about one axis only (planar motion)"),
        "joint": ("the joint hardly bends (a rigid pair)",
                  "the joint bends about one axis only (a hinge)"),
    }  # fmt: skip
    out = {"camera": "", "joint": ""}
    for key, R in checks:
        s = np.linalg.svd((R - R.mean(axis=0)).reshape(-1, 3), compute_uv=False)
        spread = float(s[0] / np.sqrt(R.shape[0]))
        if spread < MIN_ROTATION_SPREAD:
            out[key] = f"{words[key][0]}, RMS spread {np.degrees(spread):.2f} deg"
        elif s[2] < SINGLE_AXIS_RATIO * s[0]:
            out[key] = f"{words[key][1]}, singular value ratio {s[2] / s[0]:.3f}"
    return out


def _check_determined(
    est: RelposeEstimate, Ta: FloatArray, Tb: FloatArray, accept_weak: bool = False
) -> None:
    """Refuse a self-calibrated joint whose standard deviation says the motion did not
    determine it (more than :data:`UNDETERMINED_STD_FRACTION` of its distance from the
    camera). ``T_b_a``'s own spread is dominated by the reference poses' noise and is
    reported, not refused. ``accept_weak`` lets a merely narrow motion through, never a
    joint that hardly bends or bends about one axis (:func:`motion_diagnosis`): its point
    is then arbitrary, not weak."""
    if not est.self_calibrated:
        return
    worst = {}
    for key, o, cov, T in (
        ("the joint in A", est.position_in_a, est.covariance_a, Ta),
        ("the joint in B", est.position_in_b, est.covariance_b, Tb),
    ):
        # the rig's length scale: |O|, or a tenth of the camera's travel for a joint near
        # the optical centre (a pan-tilt head), whose std does not shrink with |O|
        worst[key] = largest_std(cov) / length_scale(o, T)
    bad = {k: v for k, v in worst.items() if v > UNDETERMINED_STD_FRACTION}
    if not bad:
        return
    R_w = se3.project_to_rotation(est.T_wb_wa[:3, :3])[0]
    notes = motion_diagnosis(Ta, Tb, R_w)
    if accept_weak and not notes["joint"]:
        return
    why = "; ".join(v for v in notes.values() if v) or "the motion is too narrow for the noise"
    text = ", ".join(f"{k} (std {100 * v:.0f}% of |O|)" for k, v in bad.items())
    raise DegenerateMotionError(
        f"the motion does not determine {text}: {why}. Record the rig turning about several "
        "axes while the joint bends about two or more axes"
        + (
            ", or give the joint from a fixed-joint session (--joint)"
            if est.self_calibrated
            else ""
        )
        + ("." if notes["joint"] else f"; {OVERRIDE_HINT}."),
        details={"relative_std": worst, "diagnosis": notes},
    )


def _estimate_paper(
    Ta: FloatArray, Tb: FloatArray, prior: JointPrior, unknown_scale: bool, reference: int
) -> RelposeEstimate:
    if prior.position_in_a is None:
        raise InputError(
            "the paper's method needs the joint in camera A: give --joint (the joint.yaml "
            "of a fixed-joint calibration), or self-calibrate with the refined method"
        )
    o_a_in = np.asarray(prior.position_in_a, dtype=float)
    mu_a = None
    if prior.metric and unknown_scale:
        raise InputError(
            "the paper's method takes the joint in camera A's own (scaled) units; with a "
            "metric joint use the refined method"
        )
    n = Ta.shape[0]
    R, T, O, phi, r, cov = _paper(Ta, Tb, o_a_in, reference, unknown_scale)
    _check_spread(se3.transform_points(Ta, O))
    T_b_a = se3.transforms_from_rt(R, T)
    # covariance of (R perturbation, T): rpy -> right perturbation
    G = np.zeros((6, cov.shape[0]))
    G[:3, :3] = rpy_right_jacobian(np.radians(se3.rpy_deg_from_matrix(R)))
    G[3:, 3:6] = np.eye(3)
    cov6 = G @ cov @ G.T
    O_b = phi * R @ O + T
    JOb = np.concatenate([-phi * R @ se3.skew(O) @ G[:3, :3], np.eye(3), phi * R], axis=1)
    if unknown_scale:
        JOb = np.concatenate([JOb, (R @ O)[:, None]], axis=1)
    cov_b = JOb @ cov[: JOb.shape[1], : JOb.shape[1]] @ JOb.T
    # the similarity world A -> world B: j_b = phi R_X j_a + t_X (eq. (24) at the reference)
    R_X = Tb[reference, :3, :3] @ R @ Ta[reference, :3, :3].T
    t_X = Tb[reference, :3, 3] + Tb[reference, :3, :3] @ T - phi * R_X @ Ta[reference, :3, 3]
    T_wb_wa = se3.transforms_from_rt(R_X, t_X)
    return RelposeEstimate(
        T_b_a=T_b_a,
        covariance=cov6,
        reference=reference,
        phi_ba=phi,
        phi_std=float(np.sqrt(cov[9, 9])) if unknown_scale else 0.0,
        position_in_a=O,
        position_in_b=O_b,
        covariance_a=cov[6:9, 6:9],
        covariance_b=cov_b,
        T_wb_wa=T_wb_wa,
        residual_rms=float(np.sqrt(np.mean(np.sum(r**2, axis=1)))),
        inliers=np.ones(n, dtype=bool),
        method="paper",
        unknown_scale=unknown_scale,
        self_calibrated=False,
        mu_a=mu_a,
        residuals=r,
    )


def _estimate_refined(
    Ta: FloatArray,
    Tb: FloatArray,
    prior: JointPrior,
    unknown_scale: bool,
    reference: int,
    self_cal: bool,
    reject_outliers: bool,
) -> RelposeEstimate:
    n = Ta.shape[0]
    c = np.ascontiguousarray
    Ra, ta, Rb, tb = c(Ta[:, :3, :3]), c(Ta[:, :3, 3]), c(Tb[:, :3, :3]), c(Tb[:, :3, 3])
    metric = bool(prior.metric and unknown_scale)
    L = _Layout(unknown_scale, metric)

    # ---- initialisation
    pa = None if prior.position_in_a is None else np.asarray(prior.position_in_a, float)
    pb = None if prior.position_in_b is None else np.asarray(prior.position_in_b, float)
    if pa is not None and pb is not None and not metric:
        j_a = se3.transform_points(Ta, pa)
        j_b = se3.transform_points(Tb, pb)
        _check_spread(j_a)
        R_X, t_X, phi = similarity_from_points(j_a, j_b, unknown_scale)
        o_a, o_b = pa, pb
    elif pa is not None and not metric:
        R_X, t_X, phi, o_a, o_b = _initial_lifted(Ta, Tb, pa)
    else:
        R_X, t_X, phi, o_a, o_b = _initial_lifted(Ta, Tb, None)
    if not unknown_scale:
        phi = 1.0
    mu0 = 1.0
    if metric:
        # o_a (A units) = mu_a * metric joint: least squares on whichever is known
        pairs = [(o_a, pa)] if pa is not None else []
        pairs += [(o_b / phi, pb)] if pb is not None else []
        num = sum(float(u @ v) for u, v in pairs)
        den = sum(float(v @ v) for _, v in pairs)
        mu0 = max(num / den, 1e-6) if den > 0 else 1.0
        if pa is not None:
            o_a = mu0 * pa
        if pb is not None:
            o_b = phi * mu0 * pb

    def pack(
        R_X: FloatArray, t_X: FloatArray, phi: float, o_a: FloatArray, o_b: FloatArray
    ) -> FloatArray:
        x = np.zeros(L.size)
        x[L.rot] = se3.rotvec_from_matrix(R_X)
        x[L.t], x[L.oa], x[L.ob] = t_X, o_a, o_b
        if L.logphi is not None:
            x[L.logphi] = np.log(max(phi if unknown_scale else 1.0, 1e-9))
        if L.logmu is not None:
            x[L.logmu] = np.log(mu0)
        return x

    x0 = pack(R_X, t_X, phi, o_a, o_b)
    # the lifted start can fall in a wrong minimum's basin on narrow motion (a joint
    # hundreds of units away, the rotation noise fitted at zero): without a joint, also
    # start from a joint at either camera's centre, and keep the most likely fit
    alternatives = _self_calibration_starts(Ta, Tb, unknown_scale, pack) if self_cal else []

    def unpack(
        x: FloatArray,
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float, float]:
        R = se3.matrix_from_rotvec(x[L.rot])
        ph, mu = L.scales(x)
        return R, x[L.t], x[L.oa], x[L.ob], ph, mu

    def residuals(x: FloatArray, jac: bool) -> tuple[FloatArray, FloatArray | None]:
        R, t, oa, ob, ph, _ = unpack(x)
        j_a = se3.rotate(Ra, oa) + ta
        Rja = j_a @ R.T
        r = se3.rotate(Rb, ob) + tb - ph * Rja - t
        if not jac:
            return r, None
        J = np.zeros((n, 3, L.size))
        J[:, :, L.rot] = ph * (se3.skew(Rja).reshape(-1, 3) @ R).reshape(
            n, 3, 3
        )  # R [j]x = [R j]x R
        J[:, :, L.t] = -np.eye(3)
        J[:, :, L.oa] = -ph * se3.left_multiply(R, Ra)
        J[:, :, L.ob] = Rb
        if L.logphi is not None:
            J[:, :, L.logphi] = -ph * Rja
        return r, J

    def noise_shapes(x: FloatArray) -> FloatArray:
        R, _, oa, ob, ph, _ = unpack(x)
        return lever_shapes(Rb, ob) + ph**2 * lever_shapes(se3.left_multiply(R, Ra), oa)

    def retract(x: FloatArray, dx: FloatArray) -> FloatArray:
        out = x + dx
        out[L.rot] = se3.rotvec_from_matrix(
            se3.matrix_from_rotvec(x[L.rot]) @ se3.matrix_from_rotvec(dx[L.rot])
        )
        return out

    prior_rows = _prior_rows(prior, L, metric)
    problem = estimation.LeastSquaresProblem(residuals, noise_shapes, prior_rows, retract)
    sol = estimation.solve(problem, x0, alternatives=alternatives, reject_outliers=reject_outliers)
    R_X, t_X, o_a, o_b, phi, mu = unpack(sol.x)
    j_a = se3.transform_points(Ta, o_a)
    _check_spread(j_a[sol.inliers])
    _check_information(sol.information, L, self_cal)

    # ---- the reference poses, corrected by the joint constraint (ML of the nuisance poses)
    theta_t, theta_r = sol.theta
    T_b_a, J_ref, P_post = _reference_pose(
        Ta[reference], Tb[reference], R_X, t_X, phi, o_a, o_b, theta_t, theta_r
    )
    cov6 = _relpose_covariance(Ta[reference], Tb[reference], sol, L, J_ref, P_post, unpack)
    cov = sol.covariance
    phi_std = float(phi * np.sqrt(cov[L.logphi, L.logphi])) if L.logphi is not None else 0.0
    mu_a = mu_b = mu_a_std = mu_b_std = None
    if L.logmu is not None:
        mu_a = mu
        mu_b = phi * mu
        mu_a_std = float(mu * np.sqrt(cov[L.logmu, L.logmu]))
        var_lb = cov[L.logmu, L.logmu] + cov[L.logphi, L.logphi] + 2 * cov[L.logmu, L.logphi]
        mu_b_std = float(mu_b * np.sqrt(max(var_lb, 0.0)))
    inl = sol.inliers
    X = se3.transforms_from_rt(R_X, t_X)
    return RelposeEstimate(
        T_b_a=T_b_a,
        covariance=cov6,
        reference=reference,
        phi_ba=phi,
        phi_std=phi_std,
        position_in_a=o_a,
        position_in_b=o_b,
        covariance_a=cov[L.oa, L.oa],
        covariance_b=cov[L.ob, L.ob],
        T_wb_wa=X,
        residual_rms=float(np.sqrt(np.mean(np.sum(sol.residuals[inl] ** 2, axis=1)))),
        inliers=inl,
        method="refined",
        unknown_scale=unknown_scale,
        self_calibrated=self_cal,
        mu_a=mu_a,
        mu_b=mu_b,
        mu_a_std=mu_a_std,
        mu_b_std=mu_b_std,
        noise={
            "sigma_trans": float(np.sqrt(theta_t / 2.0)),
            "sigma_rot_deg": float(np.degrees(np.sqrt(theta_r))),
        },
        residuals=sol.residuals,
    )


#: Standard deviation (in the trajectory's units) assumed for a prior joint given without one.
DEFAULT_PRIOR_STD = 1e-6


def _prior_rows(prior: JointPrior, L: _Layout, metric: bool):
    """Residual rows of the joint prior (see :class:`estimation.LeastSquaresProblem`)."""
    items = []
    for pos, cov, sl in (
        (prior.position_in_a, prior.covariance_a, L.oa),
        (prior.position_in_b, prior.covariance_b, L.ob),
    ):
        if pos is not None:
            C = np.eye(3) * DEFAULT_PRIOR_STD**2 if cov is None else np.asarray(cov, float)
            C = C + np.eye(3) * 1e-12 * max(1.0, float(np.trace(C)))
            items.append((np.asarray(pos, float), np.linalg.inv(C), sl))
    if not items:
        return None

    def rows(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        rs, Js, Ws = [], [], []
        ph, mu = L.scales(x)
        for pos, W, sl in items:
            J = np.zeros((3, L.size))
            if metric:
                # o_a = mu m_a, o_b = phi mu m_b: residual o / (mu [phi]) - m
                f = mu * (ph if sl == L.ob else 1.0)
                r = x[sl] / f - pos
                J[:, sl] = np.eye(3) / f
                J[:, L.logmu] = -x[sl] / f
                if sl == L.ob:
                    J[:, L.logphi] = -x[sl] / f
            else:
                r = x[sl] - pos
                J[:, sl] = np.eye(3)
            rs.append(r)
            Js.append(J)
            Ws.append(W)
        Wb = np.zeros((3 * len(Ws), 3 * len(Ws)))
        for k, W in enumerate(Ws):  # at most two priors
            Wb[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] = W
        return np.concatenate(rs), np.concatenate(Js), Wb

    return rows


def _check_information(H: FloatArray, L: _Layout, self_cal: bool) -> None:
    """Degenerate when the information about the relative rotation or the joint vanishes."""
    d = np.sqrt(np.maximum(np.diag(H), 1e-300))
    Hn = H / np.outer(d, d)
    w = np.linalg.eigvalsh(Hn)
    if w[0] < 1e-9 * w[-1]:
        raise DegenerateMotionError(
            "the motion does not determine the relative pose"
            + (" and the joint (self-calibration)" if self_cal else "")
            + f" (normalised information condition {w[-1] / max(w[0], 1e-300):.1e}). Record "
            "general motion: the rig turning about several axes while it moves and bends.",
            details={"information_eigenvalues": w.tolist()},
        )


def _reference_pose(
    Ta_ref: FloatArray,
    Tb_ref: FloatArray,
    R_X: FloatArray,
    t_X: FloatArray,
    phi: float,
    o_a: FloatArray,
    o_b: FloatArray,
    theta_t: float,
    theta_r: float,
    jacobian: bool = True,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``T_b_a`` at the reference instant from reference poses corrected by the constraint.

    The two measured reference poses must put the joint at one point: their correction
    ``delta = (rot_a, t_a, rot_b, t_b)`` is the minimum of ``delta^T P^-1 delta`` subject to the
    linearised constraint ``c + A delta = 0``, with ``P`` the pose noise (translation noise
    split evenly between the cameras). Returns ``T_b_a``, the Jacobian ``(6, 12)`` of
    ``T_b_a`` with respect to ``delta`` and the posterior covariance ``(12, 12)`` of ``delta``.
    """
    ref = _ReferenceCorrection(Ta_ref, Tb_ref, R_X, t_X, phi, o_a, o_b, theta_t, theta_r)
    if not jacobian:
        return ref.T_b_a, np.zeros((6, 12)), ref.P_post
    return ref.T_b_a, ref.jacobian_delta(), ref.P_post


class _ReferenceCorrection:
    """The constraint-corrected reference poses of :func:`_reference_pose` and the
    derivatives of the resulting ``T_b_a`` (rotation perturbed on the right, translation).

    ``T_b_a = [Rb_^T R_X Ra_, Rb_^T (phi R_X (ta + d_ta) + t_X - tb - d_tb)]`` with
    ``Ra_ = Ra Exp(d_ra)``, ``Rb_ = Rb Exp(d_rb)`` and ``delta = -K c``,
    ``K = P A^T (A P A^T)^-1``.
    """

    def __init__(
        self,
        Ta_ref: FloatArray,
        Tb_ref: FloatArray,
        R_X: FloatArray,
        t_X: FloatArray,
        phi: float,
        o_a: FloatArray,
        o_b: FloatArray,
        theta_t: float,
        theta_r: float,
    ) -> None:
        self.Ra, self.ta = Ta_ref[:3, :3], Ta_ref[:3, 3]
        self.Rb, self.tb = Tb_ref[:3, :3], Tb_ref[:3, 3]
        self.R_X, self.t_X, self.phi = R_X, t_X, phi
        self.o_a, self.o_b = o_a, o_b
        Ra, Rb = self.Ra, self.Rb
        self.ja = Ra @ o_a + self.ta
        self.c = Rb @ o_b + self.tb - phi * R_X @ self.ja - t_X
        self.A = np.concatenate(
            [phi * R_X @ Ra @ se3.skew(o_a), -phi * R_X, -Rb @ se3.skew(o_b), np.eye(3)], axis=1
        )
        var_ta = theta_t / (2.0 * phi**2)
        self.p = np.array([theta_r] * 3 + [var_ta] * 3 + [theta_r] * 3 + [theta_t / 2.0] * 3)
        PAt = self.p[:, None] * self.A.T
        self.Si = np.linalg.inv(self.A @ PAt)
        self.K = PAt @ self.Si
        self.delta = -self.K @ self.c
        self.P_post = np.diag(self.p) - self.K @ self.A * self.p[None, :]
        d = self.delta
        self.Ra_ = Ra @ se3.matrix_from_rotvec(d[0:3])
        self.Rb_ = Rb @ se3.matrix_from_rotvec(d[6:9])
        self.v = phi * R_X @ (self.ta + d[3:6]) + t_X - (self.tb + d[9:12])
        R_ba = self.Rb_.T @ R_X @ self.Ra_
        self.T_b_a = se3.transforms_from_rt(R_ba, self.Rb_.T @ self.v)

    def jacobian_delta(self) -> FloatArray:
        """``(6, 12)`` derivative of ``T_b_a`` with respect to ``delta``."""
        d = self.delta
        Jr = right_jacobians(np.stack([d[0:3], d[6:9]]))  # Exp(d + e) = Exp(d) Exp(Jr e)
        R_ba, t_ba = self.T_b_a[:3, :3], self.T_b_a[:3, 3]
        Jd = np.zeros((6, 12))
        Jd[:3, 0:3] = Jr[0]
        Jd[:3, 6:9] = -R_ba.T @ Jr[1]
        Jd[3:, 3:6] = self.phi * self.Rb_.T @ self.R_X
        Jd[3:, 6:9] = se3.skew(t_ba) @ Jr[1]
        Jd[3:, 9:12] = -self.Rb_.T
        return Jd

    def jacobian_params(self) -> FloatArray:
        """``(6, 13)`` derivative of ``T_b_a`` with respect to ``(R_X`` perturbed on the
        right, ``t_X, o_a, o_b, log phi)``, ``delta`` following its definition."""
        R_X, phi, Ra, Rb = self.R_X, self.phi, self.Ra, self.Rb
        e = np.eye(3)
        # derivatives of c (13, 3), A (13, 3, 12) and the diagonal of P (13, 12)
        dc = np.zeros((13, 3))
        dA = np.zeros((13, 3, 12))
        dp = np.zeros((13, 12))
        Sk = se3.skew(e)  # [e_k]x, (3, 3, 3)
        dc[0:3] = (phi * R_X @ se3.skew(self.ja)).T
        dA[0:3, :, 0:3] = phi * np.matmul(R_X @ Sk, Ra @ se3.skew(self.o_a))
        dA[0:3, :, 3:6] = -phi * np.matmul(R_X, Sk)
        dc[3:6] = -e
        dc[6:9] = (-phi * R_X @ Ra).T
        dA[6:9, :, 0:3] = phi * np.matmul(R_X @ Ra, Sk)
        dc[9:12] = Rb.T
        dA[9:12, :, 6:9] = -np.matmul(Rb, Sk)
        dc[12] = -phi * R_X @ self.ja
        dA[12, :, 0:6] = self.A[:, 0:6]
        dp[12, 3:6] = -2.0 * self.p[3:6]
        # delta = -K c, K = P A^T S^-1, S = A P A^T
        A, P, K, Si = self.A, self.p, self.K, self.Si
        dAt = np.swapaxes(dA, 1, 2)  # (13, 12, 3)
        PAt = P[:, None] * A.T
        dS = np.matmul(dA, PAt) + np.matmul(PAt.T, dAt) + np.matmul(A * dp[:, None, :], A.T)
        dK = (
            np.matmul(dp[:, :, None] * A.T, Si)
            + np.matmul(P[None, :, None] * dAt, Si)
            - np.matmul(np.matmul(K, dS), Si)
        )
        ddelta = -(dK @ self.c) - dc @ K.T  # (13, 12)
        # direct dependence of T_b_a on the parameters, delta held
        G = np.zeros((6, 13))
        G[:3, 0:3] = self.Ra_.T
        G[3:, 0:3] = -phi * self.Rb_.T @ R_X @ se3.skew(self.ta + self.delta[3:6])
        G[3:, 3:6] = self.Rb_.T
        G[3:, 12] = self.Rb_.T @ (phi * R_X @ (self.ta + self.delta[3:6]))
        return G + self.jacobian_delta() @ ddelta.T


def _relpose_covariance(Ta_ref, Tb_ref, sol, L, J_ref, P_post, unpack):
    """Covariance ``(6, 6)`` of ``T_b_a``: the similarity's uncertainty and the reference poses'."""
    R_X, t_X, o_a, o_b, phi, _ = unpack(sol.x)
    theta_t, theta_r = sol.theta
    ref = _ReferenceCorrection(Ta_ref, Tb_ref, R_X, t_X, phi, o_a, o_b, theta_t, theta_r)
    G13 = ref.jacobian_params()
    G = np.zeros((6, L.size))
    G[:, L.rot], G[:, L.t], G[:, L.oa], G[:, L.ob] = (
        G13[:, 0:3],
        G13[:, 3:6],
        G13[:, 6:9],
        G13[:, 9:12],
    )
    if L.logphi is not None:
        G[:, L.logphi] = G13[:, 12]
    return G @ sol.covariance @ G.T + J_ref @ P_post @ J_ref.T


def paper_pose_std(T_b_a: FloatArray, covariance: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Standard deviations of the paper's reported quantities from ``T_b_a``'s covariance.

    Parameters
    ----------
    T_b_a : ndarray, shape (4, 4)
    covariance : ndarray, shape (6, 6)
        Of ``(rotation perturbation of R_b_a on the right (rad), t_b_a)``.

    Returns
    -------
    rpy_std_deg : ndarray, shape (3,)
        Of roll, pitch, yaw of ``R_a_b`` (degrees).
    translation_b_in_a_std : ndarray, shape (3,)
        Of ``t_a_b = -R_b_a^T t_b_a``.
    """

    R0, t0 = T_b_a[:3, :3], T_b_a[:3, 3]
    R_ab = R0.T
    t_ab = -R_ab @ t0
    # R = R0 Exp(d) gives R_ab = Exp(-d) R0^T = R_ab Exp(-R0 d): a right perturbation of
    # R_ab, whose roll, pitch, yaw move by E^-1 of it (E: rpy_right_jacobian)
    E = rpy_right_jacobian(np.radians(se3.rpy_deg_from_matrix(R_ab)))
    G = np.zeros((6, 6))
    G[:3, :3] = -np.degrees(np.linalg.solve(E, R0))
    G[3:, :3] = se3.skew(t_ab)  # t_ab = -Exp(-d) R0^T t: moves by [t_ab]x d
    G[3:, 3:] = -R_ab
    std = np.sqrt(np.maximum(np.diag(G @ covariance @ G.T), 0.0))
    return std[:3], std[3:]
