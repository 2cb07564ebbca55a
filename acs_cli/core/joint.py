"""Joint position from camera trajectories: the paper's Algorithms I and II, and ours.

Algorithm II (fixed joint, section 3.1). While the joint stays at one world point ``p_w``,
every pose ``T_w_c[i] = [R_i, t_i]`` of a camera satisfies

    R_i o + t_i = p_w                                             (our form of eq. (11))

where ``o`` is the joint in the camera's frame. The paper writes it relative to the first
frame, ``(R^i - I) o = -T^i`` with ``H^i = inv(T_w_c[0]) T_w_c[i]`` (eq. (11)-(12)), which
treats the first pose as exact; we keep ``p_w`` as an unknown instead, so that every frame
counts alike, and weight each frame by the covariance its pose noise induces.

Algorithm I (overlap, section 2). With both cameras in one world,

    R_wa_i o_a + t_wa_i = R_wb_i o_b + t_wb_i                     (eq. (8))

Both are linear in the unknowns. The refined fixed-joint estimator is a weighted least
squares whose weights (pose noise levels) are estimated from the data
(:mod:`acs_cli.core.estimation`); the overlap is a two-body rig in one world, solved by the
rig engine (:mod:`acs_cli.core.overlap`), and :func:`overlap_motion` checks its motion.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from acs_cli.core import estimation, se3
from acs_cli.core.correlated import NOT_TESTED, CorrelatedErrors
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

#: Below this ratio of the weakest to the strongest direction of the rotation design
#: (singular values of the stacked, centred rotations) the motion may be a hinge (a
#: rotation about one axis): the fit then decides (see ``hinge_explains``).
HINGE_RATIO = 0.25
#: Below this ratio the motion is a hinge whatever the noise (numerically singular).
HINGE_RATIO_EXACT = 1e-6
#: A candidate hinge is refused when the joint's standard deviation along the weakest
#: direction exceeds this share of its distance from the camera ...
HINGE_STD_FRACTION = 0.05
#: ... or when the motion about the weak axes is within this many times the estimated
#: rotation noise (it is then noise, not motion).
HINGE_NOISE_FACTOR = 5.0
#: Smallest RMS spread of the rotations (radians, about 3 degrees) for a joint to be observable.
MIN_ROTATION_SPREAD = 0.05

METHODS = ("refined", "paper")


@dataclass(frozen=True)
class JointEstimate:
    """The joint in one or two cameras' frames.

    Attributes
    ----------
    position_in_a : ndarray, shape (3,)
        Joint in camera A's frame (the paper's ``O_A``), trajectory A's units.
    covariance_a : ndarray, shape (3, 3)
    position_in_b, covariance_b : ndarray or None
        Joint in camera B's frame (``O_B``) and its covariance, when B was given.
    scenario : str
        ``"fixed_joint"`` or ``"overlap"``.
    method : str
        ``"refined"`` or ``"paper"``.
    residual_rms : dict
        RMS of the per-frame constraint residual norm, per camera (``"a"``, ``"b"``) for
        fixed-joint, ``"ab"`` for overlap; trajectory units.
    inliers : dict
        Boolean masks ``(n,)`` of the frames used, keyed like ``residual_rms``.
    noise : dict
        Estimated pose noise: ``sigma_rot_deg`` and ``sigma_trans`` per key (refined only).
    position_in_world : dict
        Fixed-joint only: the joint's world position in each trajectory's world.
    motion : dict of str to MotionSummary
        Ball joints: how each camera (``"a"``, ``"b"``) turned (fixed joint,
        :func:`motion_summary`) or how the joint bent, in each camera's frame (overlap,
        :func:`articulation_motion`).
    """

    position_in_a: FloatArray
    covariance_a: FloatArray
    position_in_b: FloatArray | None
    covariance_b: FloatArray | None
    scenario: str
    method: str
    residual_rms: dict[str, float]
    inliers: dict[str, np.ndarray]
    noise: dict[str, dict[str, float]] = field(default_factory=dict)
    position_in_world: dict[str, FloatArray] = field(default_factory=dict)
    motion: dict[str, MotionSummary] = field(default_factory=dict)
    #: the declared joint (``ball`` or ``hinge``; ``joint --overlap --joint-type``)
    joint_type: str = "ball"
    #: a hinge's unit axis in each camera's frame (``"a"``, ``"b"``) and its std (deg)
    axis_in: dict[str, FloatArray] = field(default_factory=dict)
    axis_std_deg_in: dict[str, float] = field(default_factory=dict)
    #: per key (``"a"``, ``"b"``; ``"ab"``), the test for errors correlated over time
    #: (:mod:`acs_cli.core.correlated`); the covariances include what it found
    correlated: dict[str, CorrelatedErrors] = field(default_factory=dict)

    @property
    def std_a(self) -> FloatArray:
        return np.sqrt(np.diag(self.covariance_a))

    @property
    def std_b(self) -> FloatArray | None:
        return None if self.covariance_b is None else np.sqrt(np.diag(self.covariance_b))

    def covariance_of(self, cam: str) -> FloatArray | None:
        """``covariance_a`` or ``covariance_b`` (``cam`` is ``"a"`` or ``"b"``)."""
        return self.covariance_a if cam == "a" else self.covariance_b


@dataclass(frozen=True)
class PivotEstimate:
    """Fixed-joint result for one camera (see :func:`estimate_pivot`); ``motion`` is how
    the camera turned (:func:`motion_summary`)."""

    position_in_cam: FloatArray
    covariance: FloatArray
    position_in_world: FloatArray
    residual_rms: float
    inliers: np.ndarray
    noise: dict[str, float]
    motion: MotionSummary | None = None
    correlated: CorrelatedErrors = NOT_TESTED


def _check_method(method: str) -> None:
    if method not in METHODS:
        raise InputError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")


@dataclass(frozen=True)
class RotationSpread:
    """How much a set of rotations varies (see :func:`rotation_spread`).

    Attributes
    ----------
    ratio : float
        Weakest over strongest singular value of the stacked, centred rotations.
    axis : ndarray, shape (3,)
        The weakest direction: the axis ``v`` with ``R_i v`` most nearly constant.
    weak_rms_rad : float
        RMS rotation about the two axes across ``axis`` (radians, small-angle): how far
        the motion is from a hinge about ``axis`` (see :func:`motion_summary`).
    singular_values : ndarray, shape (3,)
        Of the stacked, centred rotations ``(3n, 3)``, largest first.
    directions : ndarray, shape (3, 3)
        Rows: the matching right singular vectors (``axis`` is the last).
    frames : int
        ``n``.
    """

    ratio: float
    axis: FloatArray
    weak_rms_rad: float
    singular_values: FloatArray
    directions: FloatArray
    frames: int

    @property
    def candidate_hinge(self) -> bool:
        return self.ratio < HINGE_RATIO


def rotation_spread(R: FloatArray, what: str) -> RotationSpread:
    """Check that rotations ``(n, 3, 3)`` vary enough to fix a point; describe how.

    The joint is fixed by how the rotations differ from their mean: stacked, centred
    rotations ``R_i - mean(R)`` must have three clearly non-zero singular values.

    Raises
    ------
    DegenerateMotionError
        Too little rotation overall.
    """
    out = spread_of(R)
    spread = float(out.singular_values[0] / np.sqrt(out.frames))
    if spread < MIN_ROTATION_SPREAD:
        raise DegenerateMotionError(
            f"{what}: too little rotation (RMS spread {np.degrees(spread):.2f} deg); the joint "
            "cannot be located. Record motion that turns the camera about the joint by tens "
            "of degrees about at least two different axes.",
            details={"rotation_spread_deg": float(np.degrees(spread))},
        )
    return out


def spread_of(R: FloatArray) -> RotationSpread:
    """How rotations ``(n, 3, 3)`` spread over their principal axes (the singular values of
    the stacked, centred ``R_i - mean(R)``), unchecked (:func:`rotation_spread` checks)."""
    n = R.shape[0]
    D = (R - R.mean(axis=0)).reshape(-1, 3)
    _, s, Vt = np.linalg.svd(D, full_matrices=False)
    ratio = float(s[2] / s[0]) if s[0] > 0 else 0.0
    return RotationSpread(ratio, Vt[2], float(s[2] / np.sqrt(n)), s, Vt, n)


@dataclass(frozen=True)
class MotionSummary:
    """How a camera turned during a fixed-joint motion, or how a joint bent (its
    articulation), in one body's frame (see :func:`motion_summary`).

    Attributes
    ----------
    axes : ndarray, shape (3, 3)
        Rows: orthonormal rotation axes in the body's frame, the one it turned about most
        first (for a near-hinge, the hinge axis); each with its largest-magnitude component
        positive.
    spread_deg : ndarray, shape (3,)
        RMS rotation about each axis (degrees, small-angle), largest first; it includes
        the rotation noise of the poses.
    ratio : float
        Weakest over strongest singular value of the stacked, centred rotations: the ratio
        the hinge rule compares with ``HINGE_RATIO`` (:func:`rotation_spread`).
    """

    axes: FloatArray
    spread_deg: FloatArray
    ratio: float

    @property
    def dominant_axis(self) -> FloatArray:
        """The axis ``(3,)`` the camera turned about most (camera frame)."""
        return np.asarray(self.axes[0])

    @property
    def near_hinge(self) -> bool:
        """``ratio < HINGE_RATIO``: a candidate hinge (a summary exists only for a motion
        that the hinge rule did not refuse, so it located the joint as a point)."""
        return self.ratio < HINGE_RATIO


def motion_summary(spread: RotationSpread) -> MotionSummary:
    """The rotation about each principal axis, from a :class:`RotationSpread`.

    With ``R_i = R_0 Exp(w_i)`` (``w_i`` in the camera's frame, centred, covariance ``C``),
    to second order ``mean (R_i - mean R)^T (R_i - mean R) = tr(C) I - C``: the squared
    singular values over ``n``, ``m_k = s_k^2 / n``, are ``tr(C) - c_k`` along ``C``'s
    eigenvectors, so the variance of the rotation about each is ``c_k = sum(m) / 2 - m_k``.
    The weakest singular direction (``spread.axis``, ``R_i v`` nearly constant) is the axis
    turned about most: a hinge's axis.

    Parameters
    ----------
    spread : RotationSpread
        Of the camera's rotations ``R_i`` (``T_world_cam``), :func:`rotation_spread`.

    Returns
    -------
    MotionSummary
    """
    m = spread.singular_values**2 / spread.frames
    c = np.maximum(0.5 * m.sum() - m, 0.0)[::-1]
    axes = np.array([_sign_convention(v) * v for v in spread.directions[::-1]])
    return MotionSummary(axes, np.degrees(np.sqrt(c)), spread.ratio)


def weakest_direction(covariance: FloatArray) -> tuple[FloatArray, float]:
    """The direction ``(3,)`` along which a joint is least determined and its std there.

    Parameters
    ----------
    covariance : ndarray, shape (3, 3)
        Of the joint (trajectory units squared).

    Returns
    -------
    direction : ndarray, shape (3,)
        Unit eigenvector of the largest eigenvalue; largest-magnitude component positive.
    std : float
        Square root of that eigenvalue (trajectory units).
    """
    w, V = np.linalg.eigh(covariance)
    v = V[:, -1]
    return _sign_convention(v) * v, float(np.sqrt(max(w[-1], 0.0)))


#: Rejected frames in a run of at least this many consecutive frames, or ...
MISFIT_RUN_FRAMES = 5
#: ... at least this share of the frames rejected, suggest a model misfit, not outliers.
MISFIT_REJECTED_FRACTION = 0.1


def rejected_runs(inliers: np.ndarray) -> np.ndarray:
    """Lengths ``(k,)`` of the runs of consecutive rejected frames, in frame order.

    Parameters
    ----------
    inliers : ndarray of bool, shape (n,)
        The frames used, in recording order.
    """
    d = np.diff(np.concatenate([[0], (~np.asarray(inliers, dtype=bool)).astype(int), [0]]))
    return np.asarray(np.flatnonzero(d == -1) - np.flatnonzero(d == 1))


def misfit_note(inliers: np.ndarray) -> str | None:
    """A sentence when the rejected frames look like a model misfit rather than outliers:
    runs of ``MISFIT_RUN_FRAMES`` or more consecutive frames, or ``MISFIT_REJECTED_FRACTION``
    of the frames or more. Gross outliers (a flipped board, a bad PnP) are isolated; a joint
    that does not stay at one point (a knee's rolling centre) loses whole stretches."""
    runs = rejected_runs(inliers)
    n, bad = int(np.asarray(inliers).size), int(runs.sum())
    long = runs[runs >= MISFIT_RUN_FRAMES]
    if long.size:
        lengths = sorted((int(x) for x in long), reverse=True)
        listed = ", ".join(str(x) for x in lengths[:-1])
        listed = f"{listed} and {lengths[-1]}" if listed else str(lengths[-1])
        return (
            f"the rejected frames form {long.size} contiguous run{'s' if long.size > 1 else ''}"
            f" of {listed} frames: the motion does not fit a fixed point there; model misfit, "
            "not outliers"
        )
    if n and bad >= MISFIT_REJECTED_FRACTION * n:
        return (
            f"{bad} of {n} frames ({100.0 * bad / n:.0f}%) were rejected: that many suggests "
            "the motion does not fit a fixed point (model misfit), not outliers"
        )
    return None


def _vec(v: FloatArray) -> str:
    return "[" + " ".join(f"{x:+.3f}" for x in v) + "]"


def near_hinge_warning(
    what: str,
    motion: dict[str, MotionSummary],
    covariance: dict[str, FloatArray],
    unit: str | dict[str, str],
) -> str | None:
    """The warning for a ball joint whose motion is nearly a hinge but that passed as a
    point, with its numbers; else None. The one wording of every mode (fixed joint, overlap,
    relative pose, rig).

    Parameters
    ----------
    what : str
        Whose motion, first in the sentence (``"camera A"``, ``"the joint"``, ``"joint hip"``).
    motion : dict of str to MotionSummary
        By body name (``"A"``, ``"thigh"``): the motion in that body's frame
        (:func:`motion_summary`, :func:`articulation_motion`). A near-hinge when any is.
    covariance : dict of str to ndarray, shape (3, 3)
        The joint's covariance in each body's frame (``unit`` squared); bodies without one
        are not named for the weak direction.
    unit : str or dict of str to str
        The length unit of the covariances, or of each body's (unknown scales).
    """
    if not any(m.near_hinge for m in motion.values()):
        return None
    first = motion[next(iter(motion))]
    ratio = min(m.ratio for m in motion.values())
    axes = [f"{_vec(m.dominant_axis)} in {body}'s frame" for body, m in motion.items()]
    s = first.spread_deg
    weak = []
    for body, cov in covariance.items():
        v, std = weakest_direction(cov)
        u = unit if isinstance(unit, str) else unit[body]
        weak.append(f"{_vec(v)} in {body} (std {std:.3g} {u})")
    return (
        f"{what}: near-hinge motion (rotation ratio {ratio:.3f} < {HINGE_RATIO}): it turns "
        f"{s[0]:.3g} deg (RMS) about the axis {' and '.join(axes)}, and only {s[1]:.2g} and "
        f"{s[2]:.2g} deg about the two others; the joint is weakly determined along "
        f"{' and '.join(weak)}. Record motion about a second axis; a joint that turns about "
        "one axis (a knee, an elbow) may be better modelled as a hinge: declare it one "
        "(--joint-type hinge, or 'type: hinge' in a rig run config)"
    )


def joint_motion_warnings(est: JointEstimate, unit: str) -> list[str]:
    """Warnings on a joint estimate's motion (:attr:`JointEstimate.motion`): a near-hinge
    (:func:`near_hinge_warning`) with, when the rejected frames look like a model misfit
    (:func:`misfit_note`), that in the same sentence; and for a fixed joint the misfit
    alone. Fixed joint: per camera (each camera's rotations); overlap: the joint (the
    articulation, in both cameras' frames).

    Parameters
    ----------
    est : JointEstimate
        From :func:`estimate_joint_fixed` or the overlap (possibly refined by a bundle
        adjustment).
    unit : str
        The trajectories' length unit.
    """
    fixed = est.scenario == "fixed_joint"
    groups = (
        [(f"camera {k.upper()}", [k], k) for k in est.motion]
        if fixed
        else ([("the joint", list(est.motion), "ab")] if est.motion else [])
    )
    out = []
    for what, cams, key in groups:
        covs = {c.upper(): cov for c in cams if (cov := est.covariance_of(c)) is not None}
        hinge = near_hinge_warning(what, {c.upper(): est.motion[c] for c in cams}, covs, unit)
        inl = est.inliers.get(key)
        misfit = None if inl is None else misfit_note(inl)
        if hinge is not None:
            out.append(hinge + ("" if misfit is None else f"; {misfit}"))
        elif misfit is not None and fixed:
            out.append(f"{what}: {misfit}")
    for key, found in est.correlated.items():
        what = f"camera {key.upper()}" if fixed else "the joint"
        note = found.message(what)
        if note is not None:
            out.append(note)
    return out


def articulation_motion(
    R_p: FloatArray, R_q: FloatArray, p: str, q: str
) -> dict[str, MotionSummary]:
    """How a joint's articulation spread over its principal axes, in each body's frame.

    The articulation is the relative rotation ``R_p_q[i] = R_p[i]^T R_q[i]`` (``q``'s frame
    in ``p``'s); its spread (:func:`spread_of`) gives the axes in ``q``'s frame, that of its
    transpose ``R_q_p`` the same axes in ``p``'s (:func:`motion_summary` each).

    Parameters
    ----------
    R_p, R_q : ndarray, shape (n, 3, 3)
        The two bodies' rotations in one world (per instant; any world shared at each
        instant).
    p, q : str
        The bodies' names (the keys returned).

    Returns
    -------
    dict of str to MotionSummary
    """
    R_pq = np.einsum("nji,njk->nik", R_p, R_q)
    return {
        p: motion_summary(spread_of(np.transpose(R_pq, (0, 2, 1)))),
        q: motion_summary(spread_of(R_pq)),
    }


def hinge_explains(
    spread: RotationSpread, covariance: FloatArray, o: FloatArray, sigma_rot_rad: float | None
) -> bool:
    """Whether a candidate hinge really leaves the joint undetermined.

    Parameters
    ----------
    spread : RotationSpread
    covariance : ndarray, shape (3, 3)
        Of the fitted joint.
    o : ndarray, shape (3,)
        The fitted joint.
    sigma_rot_rad : float, optional
        Estimated rotation noise per axis; the motion about the weak axes is noise when
        within ``HINGE_NOISE_FACTOR`` of it.
    """
    if spread.ratio < HINGE_RATIO_EXACT:
        return True
    if not spread.candidate_hinge:
        return False
    weak_std = float(np.sqrt(max(np.linalg.eigvalsh(covariance)[-1], 0.0)))
    if weak_std > HINGE_STD_FRACTION * max(float(np.linalg.norm(o)), 1e-12):
        return True
    return sigma_rot_rad is not None and spread.weak_rms_rad < HINGE_NOISE_FACTOR * sigma_rot_rad


def _hinge_error(
    what: str, axes: dict[str, FloatArray], points: dict[str, FloatArray]
) -> DegenerateMotionError:
    """The error for a hinge: the axis and its point nearest each camera, in each frame."""
    details: dict[str, object] = {}
    text = []
    for cam in axes:
        v = axes[cam] / np.linalg.norm(axes[cam])
        p = points[cam] - (points[cam] @ v) * v  # the axis point nearest camera's origin
        details[f"hinge_axis_in_{cam}"] = v.tolist()
        details[f"hinge_point_in_{cam}"] = p.tolist()
        text.append(
            f"in camera {cam.upper()}: direction [{v[0]:+.3f} {v[1]:+.3f} {v[2]:+.3f}] "
            f"through [{p[0]:+.3f} {p[1]:+.3f} {p[2]:+.3f}]"
        )
    return DegenerateMotionError(
        f"{what}: the motion turns about one axis only (a hinge), so the joint can be anywhere "
        f"on that axis ({'; '.join(text)}). Record motion about a second axis, or use the "
        "hinge axis instead of a point.",
        details=details,
    )


def _noise_dict(theta: FloatArray) -> dict[str, float]:
    """Variance components ``(theta_t, theta_r)`` to ``sigma_trans`` and ``sigma_rot_deg``."""
    return {
        "sigma_trans": float(np.sqrt(theta[0])),
        "sigma_rot_deg": float(np.degrees(np.sqrt(theta[1]))),
    }


def lever_shapes(R: FloatArray, o: FloatArray) -> FloatArray:
    """Covariance shape ``R_i [o]x [o]x^T R_i^T`` ``(n, 3, 3)`` of ``R_i Exp(n) o`` per unit
    rotation variance (the lever arm ``o`` turns rotation noise into position noise)."""
    v = se3.rotate(R, o)
    out = -v[:, :, None] * v[:, None, :]
    d = np.einsum("na,na->n", v, v)
    out[:, 0, 0] += d
    out[:, 1, 1] += d
    out[:, 2, 2] += d
    return out  # [v]x [v]x^T = |v|^2 I - v v^T


def pivot_bias_step(
    x: FloatArray,
    theta: FloatArray,
    R: FloatArray,
    information: FloatArray,
    rotation_variance: float | None = None,
) -> FloatArray:
    """The step ``(6,)`` that removes the errors-in-variables bias of the fixed-joint fit.

    The measured rotations are regressors with noise: ``R~_i = R_i Exp(n_i)``. With weights
    ``W_i = R~_i W0 R~_i^T``, ``W0 = (theta_t I + theta_r [o]x [o]x^T)^-1``, the weighted score
    ``g = sum J_i^T W_i r_i`` of ``r_i = R~_i o + t~_i - p_w`` has, at the truth, the
    expectation (to second order in ``n``, using ``E[Exp(n)] = (1 - s^2) I`` and
    ``E[[n]x M [n]x] = s^2 (M^T - tr(M) I)``)

        b = theta_r [ n W0 o ;  -sum_i R_i (2 W0 - tr(W0) I) o ]

    which pulls the joint towards the camera by about ``theta_r / spread(R)^2`` of ``|o|``.
    Solving the corrected score ``g - b = 0`` from the fit (where ``g = 0``) is one step
    ``H^-1 b``, with ``H`` the information matrix.

    Parameters
    ----------
    x : ndarray, shape (6,)
        Fitted ``(o, p_w)``.
    theta : ndarray, shape (2,)
        Noise levels ``(theta_t, theta_r)``.
    R : ndarray, shape (m, 3, 3)
        Measured rotations of the frames used.
    information : ndarray, shape (6, 6)
    rotation_variance : float, optional
        The rotation-noise variance (radians squared) the bias is proportional to; by default
        ``theta_r``; ``W0`` is always the fit's weights, from ``theta``.
    """
    o = x[:3]
    S = se3.skew(o)
    W0 = np.linalg.inv(theta[0] * np.eye(3) + theta[1] * S @ S.T)
    s2 = float(theta[1] if rotation_variance is None else rotation_variance)
    b = np.concatenate(
        [
            s2 * R.shape[0] * W0 @ o,
            -s2 * R.sum(axis=0) @ ((2.0 * W0 - np.trace(W0) * np.eye(3)) @ o),
        ]
    )
    return np.asarray(np.linalg.solve(information, b))


#: The errors-in-variables correction (:func:`pivot_bias_step`) is applied only when its own
#: standard error is within this many of the joint's standard deviations (Mahalanobis
#: distance, :func:`pivot_bias_correction`).
BIAS_STEP_MAX_STD = 1.0


def rotation_variance_std(theta: FloatArray, L: FloatArray) -> float:
    """Standard error of the ML rotation-noise variance ``theta_r`` (radians squared).

    From the Fisher information of the variance components of ``Sigma_i = theta_t I +
    theta_r L_i``, ``I_kl = 1/2 sum_i tr(S_i C_k S_i C_l)`` (``S_i = Sigma_i^-1``, ``C_0 = I``,
    ``C_1 = L_i``), with ``theta_t`` unknown too: ``Var(theta_r) = 1 / (I_rr - I_rt^2 / I_tt)``.
    Rotation noise reaches a fixed-joint residual only through the lever arm ``|o|``; with
    the joint at the optical centre ``L_i`` vanishes and this is infinite.

    Parameters
    ----------
    theta : ndarray, shape (2,)
        ``(theta_t, theta_r)``: translation (length units squared) and rotation (radians
        squared) noise variances.
    L : ndarray, shape (m, 3, 3)
        Lever shapes of the frames used (:func:`lever_shapes`).

    Returns
    -------
    float
        ``inf`` when the information about ``theta_r`` vanishes.
    """
    F, _ = estimation.variance_component_information(theta, L)
    (i_tt, i_tr), (_, i_rr) = 0.5 * F
    schur = i_rr - i_tr**2 / i_tt if i_tt > 0.0 else 0.0
    return float(1.0 / np.sqrt(schur)) if schur > 1e-12 * max(i_rr, 1e-300) else float("inf")


def pivot_bias_correction(
    x: FloatArray, theta: FloatArray, R: FloatArray, information: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The errors-in-variables correction of a fixed-joint fit, when the data determine it.

    The bias (:func:`pivot_bias_step`) is proportional to the rotation-noise variance
    ``theta_r``: the step is ``theta_r s`` and its standard error ``v = std(theta_r) s``
    (:func:`rotation_variance_std`). A fixed-joint fit sees rotation noise only through the
    lever arm ``|o|``: with the joint near the optical centre (a pan-tilt head, ``|o|`` of
    centimetres against millimetres of translation noise) ``theta_r`` is hardly determined,
    its estimate wanders (17 deg fitted for 1 deg of true noise at ``|o|`` = 1 cm) and the
    correction moved the joint by up to 13 of its standard deviations, while the bias there
    is a small fraction of one. The step is therefore taken only when ``v``'s Mahalanobis
    length ``sqrt(v^T H v)`` is within ``BIAS_STEP_MAX_STD``, and then its uncertainty
    ``v v^T`` joins the covariance. That length does not depend on the number of frames
    (the bias and the precision both grow as ``sqrt(n)``); measured: 0.03-0.3 for joints
    0.2-1.5 m away, 0.7 at 5 cm, 2.5-4.4 at 1 cm (1 deg, 5 mm of pose noise).

    Parameters
    ----------
    x : ndarray, shape (6,)
        Fitted ``(o, p_w)``, trajectory units.
    theta : ndarray, shape (2,)
        Fitted noise levels ``(theta_t, theta_r)``.
    R : ndarray, shape (m, 3, 3)
        Measured rotations of the frames used.
    information : ndarray, shape (6, 6)
        The fit's information matrix ``H``.

    Returns
    -------
    step : ndarray, shape (6,)
        To add to ``x``; zero when the correction is not determined.
    covariance : ndarray, shape (6, 6)
        To add to the fit's covariance (``v v^T``, or zero).
    """
    s = pivot_bias_step(x, theta, R, information, rotation_variance=1.0)
    v = rotation_variance_std(theta, lever_shapes(R, x[:3])) * s
    if not np.all(np.isfinite(v)) or float(v @ information @ v) > BIAS_STEP_MAX_STD**2:
        return np.zeros(6), np.zeros((6, 6))
    return float(theta[1]) * s, np.outer(v, v)


def pivot_motion(
    T_w_c: FloatArray, what: str = "camera"
) -> tuple[FloatArray, RotationSpread, Callable[[], DegenerateMotionError]]:
    """Check that a fixed-joint motion can locate the joint (Algorithm II).

    Parameters
    ----------
    T_w_c : ndarray, shape (n, 4, 4)
        Poses ``T_world_cam``.
    what : str
        Name used in messages.

    Returns
    -------
    T : ndarray, shape (n, 4, 4)
        The poses, checked.
    spread : RotationSpread
        Of the rotations (:func:`rotation_spread`).
    hinge : callable
        The error for a motion about one axis (the axis and a point on it), for a fit that
        finds a hinge (:func:`hinge_explains`).

    Raises
    ------
    DegenerateMotionError
        Fewer than 3 poses, too little rotation, or rotation about exactly one axis.
    """
    T = se3.check_transforms(T_w_c, name=f"{what} poses")
    n = T.shape[0]
    if n < 3:
        raise DegenerateMotionError(
            f"{what}: {n} poses; a fixed-joint calibration needs at least 3"
        )
    R, t = T[:, :3, :3], T[:, :3, 3]
    spread = rotation_spread(R, what)

    def hinge() -> DegenerateMotionError:
        # any point on the axis fits: the truncated least-squares point (p_w eliminated)
        D = (R - R.mean(axis=0)).reshape(-1, 3)
        point, *_ = np.linalg.lstsq(D, -(t - t.mean(axis=0)).reshape(-1), rcond=HINGE_RATIO)
        cam = what.split()[-1].lower() if what.startswith("camera ") else "a"
        return _hinge_error(what, {cam: spread.axis}, {cam: point})

    if spread.ratio < HINGE_RATIO_EXACT:
        raise hinge()
    return T, spread, hinge


def estimate_pivot(
    T_w_c: FloatArray, method: str = "refined", what: str = "camera"
) -> PivotEstimate:
    """Joint in one camera's frame from a fixed-joint motion (Algorithm II).

    Parameters
    ----------
    T_w_c : ndarray, shape (n, 4, 4)
        Poses ``T_world_cam`` (any world; one that is fixed during the motion).
    method : {"refined"}
        The world joint ``p_w`` as an unknown, frames weighted by their estimated noise,
        gross outliers rejected, the errors-in-variables bias of noisy rotations removed
        when the data determine it (:func:`pivot_bias_correction`). The paper's form (eq.
        (12) relative to the first frame) is :func:`acs_cli.core.paper.algorithm_2_pivot`.
    what : str
        Name used in messages.

    Returns
    -------
    PivotEstimate

    Raises
    ------
    DegenerateMotionError
        Too few frames, too little rotation, or rotation about a single axis.
    """
    if method != "refined":
        _check_method(method)
        raise InputError(
            "the paper's Algorithm II is acs_cli.core.paper.algorithm_2_pivot; "
            "estimate_pivot is the refined estimator"
        )
    T, spread, hinge = pivot_motion(T_w_c, what)
    n = T.shape[0]
    R, t = np.ascontiguousarray(T[:, :3, :3]), np.ascontiguousarray(T[:, :3, 3])
    # unknowns x = (o, p_w); residual r_i = R_i o + t_i - p_w, linear in x
    J = np.concatenate([R, np.broadcast_to(-np.eye(3), (n, 3, 3))], axis=2)

    def residuals(x: FloatArray, jac: bool) -> tuple[FloatArray, FloatArray | None]:
        return se3.rotate(R, x[:3]) + t - x[3:], J

    def noise_shapes(x: FloatArray) -> FloatArray:
        return lever_shapes(R, x[:3])

    x0, *_ = np.linalg.lstsq(J.reshape(-1, 6), -t.reshape(-1), rcond=None)
    sol = estimation.solve(estimation.LeastSquaresProblem(residuals, noise_shapes), x0)
    inl = sol.inliers
    # whether a hinge explains the motion is a question of its geometry: the model's covariance
    cov_model = sol.motion_covariance[:3, :3]
    if hinge_explains(spread, cov_model, sol.x[:3], float(np.sqrt(sol.theta[1]))):
        raise hinge()
    step, cov_step = pivot_bias_correction(sol.x, sol.theta, R[inl], sol.information)
    x = sol.x + step
    rms = float(np.sqrt(np.mean(np.sum(sol.residuals[inl] ** 2, axis=1))))
    return PivotEstimate(
        position_in_cam=x[:3],
        covariance=sol.covariance[:3, :3] + cov_step[:3, :3],
        position_in_world=x[3:],
        residual_rms=rms,
        inliers=inl,
        noise=_noise_dict(sol.theta),
        motion=motion_summary(spread),
        correlated=sol.correlated,
    )


def estimate_joint_fixed(
    T_wa_a: FloatArray, T_wb_b: FloatArray | None = None, method: str = "refined"
) -> JointEstimate:
    """Algorithm II for one or two cameras, each trajectory in its own world
    (:func:`estimate_pivot` each; the paper's form is
    :func:`acs_cli.core.paper.algorithm_2_fixed_joint`).

    Parameters
    ----------
    T_wa_a : ndarray, shape (n, 4, 4)
        Camera A's poses ``T_world_a`` during a fixed-joint motion.
    T_wb_b : ndarray, shape (m, 4, 4), optional
        Camera B's poses in its own world (need not be paired with A's).
    method : {"refined"}
    """
    a = estimate_pivot(T_wa_a, method, "camera A")
    b = None if T_wb_b is None else estimate_pivot(T_wb_b, method, "camera B")
    return joint_of_pivots(a, b, method)


def joint_of_pivots(a: PivotEstimate, b: PivotEstimate | None, method: str) -> JointEstimate:
    """The fixed-joint :class:`JointEstimate` of camera A's and (optionally) B's pivots."""
    rms = {"a": a.residual_rms}
    inl = {"a": a.inliers}
    noise = {"a": a.noise} if a.noise else {}
    world = {"a": a.position_in_world}
    motion = {} if a.motion is None else {"a": a.motion}
    correlated = {"a": a.correlated}
    if b is not None:
        correlated["b"] = b.correlated
        rms["b"], inl["b"], world["b"] = b.residual_rms, b.inliers, b.position_in_world
        if b.noise:
            noise["b"] = b.noise
        if b.motion is not None:
            motion["b"] = b.motion
    return JointEstimate(
        position_in_a=a.position_in_cam,
        covariance_a=a.covariance,
        position_in_b=None if b is None else b.position_in_cam,
        covariance_b=None if b is None else b.covariance,
        scenario="fixed_joint",
        method=method,
        residual_rms=rms,
        inliers=inl,
        noise=noise,
        position_in_world=world,
        motion=motion,
        correlated=correlated,
    )


@dataclass(frozen=True)
class OverlapMotion:
    """Paired poses of two cameras in one world that can locate their joint (Algorithm I),
    checked by :func:`overlap_motion`.

    Attributes
    ----------
    T_w_a, T_w_b : ndarray, shape (n, 4, 4)
        The paired ``T_world_a``, ``T_world_b``.
    spread : RotationSpread
        Of the articulation ``R_a_b[i] = R_wa[i]^T R_wb[i]`` (:func:`rotation_spread`).
    """

    T_w_a: FloatArray
    T_w_b: FloatArray
    spread: RotationSpread

    def hinge_error(self) -> DegenerateMotionError:
        """The error for an articulation about one axis: the axis in both frames, through
        the truncated least-squares joint of eq. (9)."""
        Ra, Rb = self.T_w_a[:, :3, :3], self.T_w_b[:, :3, :3]
        R_ab = np.einsum("nji,njk->nik", Ra, Rb)
        axis_a = R_ab.mean(axis=0) @ self.spread.axis  # R_ab_i axis_b: one axis in A
        A6 = np.concatenate([Ra, -Rb], axis=2).reshape(-1, 6)
        rhs = (self.T_w_b[:, :3, 3] - self.T_w_a[:, :3, 3]).reshape(-1)
        sol, *_ = np.linalg.lstsq(A6, rhs, rcond=HINGE_RATIO)
        return _hinge_error(
            "the joint cannot be observed",
            {"a": axis_a, "b": self.spread.axis},
            {"a": sol[:3], "b": sol[3:]},
        )


def overlap_motion(T_w_a: FloatArray, T_w_b: FloatArray) -> OverlapMotion:
    """Check that paired poses of two cameras in one world can locate their joint.

    The articulation ``R_a_b[i] = R_wa[i]^T R_wb[i]`` must vary about at least two axes:
    a rigid pair has no joint to find, and a hinge leaves the joint anywhere on its axis
    (a hinge judged by the fit's noise is :func:`hinge_explains`, after the fit).

    Parameters
    ----------
    T_w_a, T_w_b : ndarray, shape (n, 4, 4)
        Paired ``T_world_a`` and ``T_world_b`` in the same world frame.

    Raises
    ------
    InputError
        Poses that are not paired rigid transforms.
    DegenerateMotionError
        Fewer than 3 frames, a rigid pair, or an articulation about exactly one axis.
    """
    Ta, Tb = se3.check_paired_transforms(T_w_a, T_w_b, "overlap")
    n = Ta.shape[0]
    if n < 3:
        raise DegenerateMotionError(f"{n} paired poses; an overlap calibration needs at least 3")
    R_ab = np.einsum("nji,njk->nik", Ta[:, :3, :3], Tb[:, :3, :3])
    try:
        spread = rotation_spread(R_ab, "relative rotation between A and B")
    except DegenerateMotionError as exc:
        raise DegenerateMotionError(
            "the joint cannot be observed: "
            + exc.message
            + " A rigid pair (no articulation) has no joint to find; move the joint "
            "between frames.",
            details=exc.details,
        ) from None
    motion = OverlapMotion(Ta, Tb, spread)
    if spread.ratio < HINGE_RATIO_EXACT:
        raise motion.hinge_error()
    return motion


# ----------------------------------------------------------------------------- hinge joints


@dataclass(frozen=True)
class HingeEstimate:
    """A hinge (a joint that turns about one axis) in one camera's frame.

    See :func:`estimate_hinge_fixed`. The hinge is the line ``{point_in_cam + s axis_in_cam}``
    (camera frame); in the trajectory's world it is ``{point_in_world + s axis_in_world}``.

    Attributes
    ----------
    axis_in_cam : ndarray, shape (3,)
        Unit axis ``u`` in the camera's frame; its largest-magnitude component is positive.
    point_in_cam : ndarray, shape (3,)
        The axis point nearest the camera's optical centre (``point_in_cam @ axis_in_cam``
        is 0), trajectory units.
    covariance_axis : ndarray, shape (3, 3)
        Covariance of ``axis_in_cam`` (rank 2: perpendicular to the axis; radians squared).
    covariance_point : ndarray, shape (3, 3)
        Covariance of ``point_in_cam`` (trajectory units squared). It includes the shift of
        the nearest point along the axis that an error of the axis's direction causes.
    axis_std_deg : float
        RMS angle between the estimated and the true axis, ``sqrt(trace(covariance_axis))``
        in degrees (each of the two perpendicular directions has ``axis_std_deg / sqrt(2)``).
    angle_range_deg : float
        The angle the hinge swept (largest minus smallest turn of the frames used).
    residual_rms : float
        RMS norm of the per-frame point residual ``R_i o + t_i - p_w`` (trajectory units).
    inliers : ndarray of bool, shape (n,)
        The frames used.
    noise : dict
        Estimated pose noise: ``sigma_rot_deg`` (from the axis fit) and ``sigma_trans``
        (from the point fit); empty for ``method="paper"``.
    axis_in_world : ndarray, shape (3,)
        The axis in the trajectory's world, ``a_w = R_i u``.
    point_in_world : ndarray, shape (3,)
        ``p_w = R_i o + t_i``: where ``point_in_cam`` stays in the world.
    method : str
        ``"refined"`` or ``"paper"``.
    """

    axis_in_cam: FloatArray
    point_in_cam: FloatArray
    covariance_axis: FloatArray
    covariance_point: FloatArray
    axis_std_deg: float
    angle_range_deg: float
    residual_rms: float
    inliers: np.ndarray
    noise: dict[str, float]
    axis_in_world: FloatArray
    point_in_world: FloatArray
    method: str = "refined"

    @property
    def std_point(self) -> FloatArray:
        return np.sqrt(np.diag(self.covariance_point))


def perpendicular_basis(v: FloatArray) -> FloatArray:
    """An orthonormal basis ``(3, 2)`` of the plane perpendicular to unit ``v`` ``(3,)``
    (a deterministic, continuous choice away from ``v``'s smallest component's axis)."""
    e = np.zeros(3)
    e[int(np.argmin(np.abs(v)))] = 1.0
    b1 = np.cross(v, e)
    b1 /= np.linalg.norm(b1)
    return np.stack([b1, np.cross(v, b1)], axis=1)


def _unit_chart(v0: FloatArray, B0: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Unit vector ``v = (v0 + B0 y) / |v0 + B0 y|`` ``(3,)`` and ``dv/dy`` ``(3, 2)``."""
    w = v0 + B0 @ y
    nw = float(np.linalg.norm(w))
    v = w / nw
    return v, (np.eye(3) - np.outer(v, v)) @ B0 / nw


class _AxisProblem:
    """The hinge-axis constraint ``R_i u = a_w`` as a :class:`estimation.LeastSquaresProblem`.

    Parameters ``x = (y, z)`` ``(4,)``: ``u`` and ``a_w`` in charts around starting unit
    vectors ``u0``, ``a0`` (:func:`_unit_chart`, fixed tangent bases ``B0``, ``C0``). Residual
    per frame ``r_i = [B0^T (R_i^T a_w - u), 0]``: with ``R~_i = R_i Exp(n_i)`` it is
    ``-B0^T (n_i x u)`` to first order, covariance ``theta_r B0^T (I - u u^T) B0``, the
    rotation noise across the axis (the third component is identically zero).
    """

    def __init__(self, R: FloatArray, u0: FloatArray, a0: FloatArray) -> None:
        self.R, self.u0, self.a0 = R, u0, a0
        self.B0, self.C0 = perpendicular_basis(u0), perpendicular_basis(a0)

    def vectors(self, x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``u``, ``a_w`` and their derivatives ``(3, 2)`` at ``x``."""
        u, du = _unit_chart(self.u0, self.B0, x[:2])
        a, da = _unit_chart(self.a0, self.C0, x[2:])
        return u, a, du, da

    def residuals(self, x: FloatArray, jac: bool) -> tuple[FloatArray, FloatArray | None]:
        n = self.R.shape[0]
        u, a, du, da = self.vectors(x)
        c = np.einsum("nji,j->ni", self.R, a)  # R_i^T a
        r = np.zeros((n, 3))
        r[:, :2] = (c - u) @ self.B0
        if not jac:
            return r, None
        J = np.zeros((n, 3, 4))
        J[:, :2, :2] = -self.B0.T @ du
        J[:, :2, 2:] = np.einsum("ij,nkj,kl->nil", self.B0.T, self.R, da)  # B0^T R_i^T da
        return r, J

    def noise_shapes(self, x: FloatArray) -> FloatArray:
        u = self.vectors(x)[0]
        L = np.zeros((self.R.shape[0], 3, 3))
        L[:, :2, :2] = self.B0.T @ (np.eye(3) - np.outer(u, u)) @ self.B0
        return L

    def problem(self) -> estimation.LeastSquaresProblem:
        return estimation.LeastSquaresProblem(self.residuals, self.noise_shapes)

    def axis_covariance(self, x: FloatArray, cov: FloatArray) -> FloatArray:
        """Covariance ``(3, 3)`` of ``u`` from the parameters' covariance ``(4, 4)``."""
        du = self.vectors(x)[2]
        return np.asarray(du @ cov[:2, :2] @ du.T)


def _hinge_angle_range_deg(R: FloatArray, u: FloatArray, a: FloatArray) -> float:
    """Swept angle (degrees) of rotations ``R`` ``(n, 3, 3)`` about the world axis ``a``."""
    w = perpendicular_basis(u)[:, 0]
    v = se3.rotate(R, w)  # (n, 3): w in the world, turning about a
    v0 = v[0]
    phi = np.arctan2(np.cross(v0, v) @ a, v @ v0)
    mean = np.arctan2(np.mean(np.sin(phi)), np.mean(np.cos(phi)))
    centred = np.angle(np.exp(1j * (phi - mean)))
    return float(np.degrees(centred.max() - centred.min()))


def _sign_convention(u: FloatArray) -> float:
    """``+1`` or ``-1``: the sign that makes ``u``'s largest-magnitude component positive."""
    return 1.0 if u[int(np.argmax(np.abs(u)))] >= 0.0 else -1.0


def _ball_error(what: str, pivot: PivotEstimate, ratio: float) -> DegenerateMotionError:
    o = pivot.position_in_cam
    return DegenerateMotionError(
        f"{what}: the motion turns about more than one axis (weakest/strongest rotation "
        f"ratio {ratio:.3f}); this is a ball joint, use estimate_pivot / --type ball "
        f"(it puts the joint at [{o[0]:+.3f} {o[1]:+.3f} {o[2]:+.3f}] in the camera's frame).",
        details={"rotation_ratio": ratio, "ball_joint_in_cam": o.tolist()},
    )


#: A fit whose residual RMS is below this share of the data's scale is exact (noise-free
#: data): there is no noise to estimate (and its estimate would underflow).
EXACT_FIT = 1e-12


def _solve_or_exact(
    problem: estimation.LeastSquaresProblem, x0: FloatArray, scale: float
) -> tuple[estimation.LeastSquaresResult, bool]:
    """:func:`estimation.solve` from ``x0``, or ``x0`` itself when it fits exactly (the
    second value): unweighted covariance, every frame kept."""
    r, J = problem.residuals(x0, True)
    if J is None or float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) > EXACT_FIT * scale:
        return estimation.solve(problem, x0), False
    n, p = r.shape[0], J.shape[2]
    s2 = float(np.sum(r**2)) / max(r.size - p, 1)
    H = J.reshape(-1, p).T @ J.reshape(-1, p)
    result = estimation.LeastSquaresResult(
        x=x0,
        covariance=s2 * np.linalg.pinv(H, hermitian=True),
        theta=np.array([s2, s2]),
        residuals=r,
        mahalanobis_sq=np.zeros(n),
        inliers=np.ones(n, dtype=bool),
        iterations=0,
        converged=True,
        information=H,
    )
    return result, True


def estimate_hinge_fixed(
    T_w_c: FloatArray, what: str = "camera", *, method: str = "refined"
) -> HingeEstimate:
    """A hinge's axis and line in one camera's frame from a fixed-joint motion.

    The camera's body turns about a hinge whose axis stays fixed in the world (the other
    body held still). Every pose ``T_w_c[i] = [R_i, t_i]`` then satisfies, for the axis
    direction ``u`` (camera frame) and ``a_w`` (world), and every point ``o`` of the axis,

        R_i u = a_w                                               (axis)
        R_i o + t_i = p_w                                         (eq. (11)-(12))

    The second is the pivot constraint of Algorithm II (:func:`estimate_pivot`; the paper's
    eq. (11)-(12)), which a hinge satisfies for any ``o = o_0 + s u``: the gauge is fixed by
    ``o . u = 0``, the axis point nearest the camera's optical centre.

    ``"refined"`` (maximum likelihood to first order; pose noise
    ``[R_i Exp(n_i), t_i + m_i]``, isotropic per axis):

    1. ``u, a_w``: the ML estimate of ``R_i u = a_w`` under isotropic rotation noise is the
       top singular pair of ``sum R_i`` (equivalently the weakest direction of the
       stacked, centred rotations, :func:`rotation_spread`); it starts a Levenberg-Marquardt
       fit of ``B^T (R_i^T a_w - u)`` (residual across the axis, covariance
       ``sigma_rot^2 I``) by :func:`estimation.solve`, which estimates the rotation noise
       and rejects outlier frames. ``covariance_axis`` is from its information matrix.
    2. ``o = B y`` (``B`` ``(3, 2)`` a basis perpendicular to ``u``) and ``p_w`` ``(3,)``:
       the weighted least squares of ``R_i B y + t_i - p_w`` with covariance
       ``sigma_t^2 I + sigma_rot^2 R_i [o]x [o]x^T R_i^T`` per frame (noise levels
       estimated, outliers rejected; the frames of step 1's inliers), then the
       errors-in-variables correction of :func:`pivot_bias_step` restricted to the plane
       (with step 1's rotation noise: the point fit sees it only through the lever arm).
       ``covariance_point = B Cov(y) B^T + (o^T Cov(u) o) u u^T``: an axis error ``du``
       moves the nearest point along the axis by ``-(o . du)``.

    ``"paper"``: the axis by the same singular vector, unweighted; the point by linear
    least squares of eq. (12) relative to the first frame, ``(R^i - I) B y = -T^i``;
    no noise estimation or outlier rejection. Its point covariance is the naive one of
    that regression (it ignores that every row shares the first frame's error) and is
    optimistic.

    Noise-free poses (a fit exact to ``EXACT_FIT``) are solved directly, with no noise to
    estimate.

    Parameters
    ----------
    T_w_c : ndarray, shape (n, 4, 4)
        Poses ``T_world_cam`` (any world fixed during the motion), trajectory units.
    what : str
        Name used in messages (e.g. ``"camera A"``).
    method : {"refined", "paper"}
        Keyword only.

    Returns
    -------
    HingeEstimate
        Axis and nearest point in the camera's frame, with covariances; angles in degrees.

    Raises
    ------
    DegenerateMotionError
        Fewer than 3 poses; too little rotation (:func:`rotation_spread`); or motion about
        more than one axis, judged as :func:`estimate_pivot` judges a hinge (when it can
        locate the joint as a point, the motion is a ball joint's).
    """
    _check_method(method)
    T = se3.check_transforms(T_w_c, name=f"{what} poses")
    n = T.shape[0]
    if n < 3:
        raise DegenerateMotionError(
            f"{what}: {n} poses; a fixed-joint hinge calibration needs at least 3"
        )
    R, t = np.ascontiguousarray(T[:, :3, :3]), np.ascontiguousarray(T[:, :3, 3])
    spread = rotation_spread(R, what)
    if spread.ratio >= HINGE_RATIO_EXACT:
        try:
            pivot = estimate_pivot(T, "refined", what)
        except DegenerateMotionError:
            pass  # a hinge: the point is not determined
        else:
            raise _ball_error(what, pivot, spread.ratio)
    u0 = spread.axis
    a0 = R.sum(axis=0) @ u0
    a0 /= np.linalg.norm(a0)
    axis_problem = _AxisProblem(R, u0, a0)
    cov_y: np.ndarray
    if method == "paper":
        r_ax, J_ax = axis_problem.residuals(np.zeros(4), True)
        if J_ax is None:
            raise ValueError("the axis problem gave no Jacobian")
        Jf = J_ax[:, :2].reshape(-1, 4)
        theta_r = float(np.sum(r_ax**2) / max(2 * n - 4, 1))
        cov_axis = axis_problem.axis_covariance(np.zeros(4), theta_r * np.linalg.inv(Jf.T @ Jf))
        u, a = u0, a0
        B = perpendicular_basis(u)
        # eq. (11)-(12): H^i = inv(T_0) T_i, (R^i - I) B y = -T^i, i = 1..n-1
        H = se3.invert_transforms(T[0]) @ T[1:]
        M = np.einsum("nij,jk->nik", H[:, :3, :3] - np.eye(3), B).reshape(-1, 2)
        rhs = -H[:, :3, 3].reshape(-1)
        y, *_ = np.linalg.lstsq(M, rhs, rcond=None)
        res = (M @ y - rhs).reshape(-1, 3)
        s2 = float(np.sum(res**2) / max(res.size - 2, 1))
        cov_y = s2 * np.linalg.inv(M.T @ M)
        o = B @ y
        p_w = se3.transform_points(T[0], o)
        rms = float(np.sqrt(np.mean(np.sum(res**2, axis=1))))
        inl = np.ones(n, dtype=bool)
        noise: dict[str, float] = {}
        R_used = R
    else:
        ax, _ = _solve_or_exact(axis_problem.problem(), np.zeros(4), 1.0)
        u, a, _, _ = axis_problem.vectors(ax.x)
        # the residual has 2 (not 3) dimensions a frame: solve's ML variance correction
        # 3m / (3m - 4) becomes 2m / (2m - 4)
        m = int(ax.inliers.sum())
        dof_fix = (2.0 * m / max(2 * m - 4, 1)) / (3.0 * m / (3 * m - 4))
        theta_r = float(ax.theta[1]) * dof_fix
        cov_axis = axis_problem.axis_covariance(ax.x, ax.covariance) * dof_fix
        keep = np.flatnonzero(ax.inliers)
        R_used, t_used = R[keep], t[keep]
        B = perpendicular_basis(u)
        RB = np.einsum("nij,jk->nik", R_used, B)
        J = np.concatenate([RB, np.broadcast_to(-np.eye(3), (m, 3, 3))], axis=2)

        def residuals(x: FloatArray, jac: bool) -> tuple[FloatArray, FloatArray | None]:
            return np.einsum("nij,j->ni", RB, x[:2]) + t_used - x[2:], J

        def noise_shapes(x: FloatArray) -> FloatArray:
            return lever_shapes(R_used, B @ x[:2])

        x0, *_ = np.linalg.lstsq(J.reshape(-1, 5), -t_used.reshape(-1), rcond=None)
        sol, exact = _solve_or_exact(
            estimation.LeastSquaresProblem(residuals, noise_shapes),
            x0,
            1.0 + float(np.abs(t_used).max()),
        )
        used = sol.inliers
        x = sol.x
        if not exact:
            # the score's bias, with the rotation noise of the axis fit (the point fit
            # tells it only through the lever arm |o|: not at all for a camera on the axis)
            x6 = np.concatenate([B @ x[:2], x[2:]])
            theta_bias = np.array([sol.theta[0], theta_r])
            b6 = pivot_bias_step(x6, theta_bias, R_used[used], np.eye(6))
            x = x + np.linalg.solve(sol.information, np.concatenate([B.T @ b6[:3], b6[3:]]))
        o, p_w = B @ x[:2], x[2:]
        cov_y = sol.covariance[:2, :2]
        rms = float(np.sqrt(np.mean(np.sum(sol.residuals[used] ** 2, axis=1))))
        inl = np.zeros(n, dtype=bool)
        inl[keep[used]] = True
        R_used = R_used[used]
        noise = {
            "sigma_trans": float(np.sqrt(sol.theta[0])),
            "sigma_rot_deg": float(np.degrees(np.sqrt(theta_r))),
        }
    cov_point = B @ cov_y @ B.T + float(o @ cov_axis @ o) * np.outer(u, u)
    sign = _sign_convention(u)
    return HingeEstimate(
        axis_in_cam=sign * u,
        point_in_cam=o,
        covariance_axis=cov_axis,
        covariance_point=cov_point,
        axis_std_deg=float(np.degrees(np.sqrt(max(np.trace(cov_axis), 0.0)))),
        angle_range_deg=_hinge_angle_range_deg(R_used, u, a),
        residual_rms=rms,
        inliers=inl,
        noise=noise,
        axis_in_world=sign * a,
        point_in_world=p_w,
        method=method,
    )
