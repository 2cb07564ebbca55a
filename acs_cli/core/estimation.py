"""Weighted least squares with estimated noise levels, shared by every refined estimator.

Each refined estimator stacks one 3-vector residual a frame, ``r_i`` (``(n, 3)``), whose
covariance is modelled with two unknown variance components

    Sigma_i = theta_t I + theta_r L_i

``theta_t`` for translation noise and ``theta_r`` for rotation noise seen through a lever
arm, e.g. ``L_i = R_i [o]x [o]x^T R_i^T`` for a joint at ``o``. Frames are weighted by
``Sigma_i^{-1}``; the variance components are estimated from the residuals by maximum
likelihood. The two alternate: with the weights held, the whitened residuals
``chol(W_i)^T r_i`` (and prior rows ``chol(W_p)^T r_p``) are minimised by the project's
least-squares engine (:func:`acs_cli.core.lsq.solve`, Levenberg-Marquardt on the normal
equations with analytic Jacobians ``(n, 3, p)``: a few unknowns and many frames, so one
``p x p`` product a step; MINPACK's QR of the tall Jacobian was 2-2.4x slower at 100,000
frames), then the noise levels are re-fitted. All per-frame work is
batched (no Python loop over frames).

Gross outliers are rejected by externally studentised residuals (Cook & Weisberg,
*Residuals and Influence in Regression*, 1982, ch. 2), so that the test holds at any number
of frames. With ``e_i = chol(W_i)^T r_i`` the whitened residual of frame ``i`` (dimension
``m``, 3 here) and ``H_ii`` its ``m x m`` block of the hat matrix, the residual's
leave-one-out prediction error has squared whitened norm ``T_i = e_i^T (I - H_ii)^{-1} e_i``
(exact for a linear model), and the fit without frame ``i`` has the whitened residual power
``S - T_i`` over ``nu - m`` degrees of freedom (``S = sum e_i^T e_i`` over the ``k`` kept
frames, ``nu = m k - p - 1``: ``p`` unknowns and the ratio of the two noise levels). Then
``F_i = (T_i / m) / ((S - T_i) / (nu - m))`` follows Fisher's ``F(m, nu - m)`` under Gaussian
noise with one unknown scale: the leverage (which shrinks a fitted residual) and the
estimated noise level (which the frame itself inflates) are both accounted for, which the
chi-square(3) test of the raw Mahalanobis distance was not (it rejected a clean frame
in 74% of 4-frame recordings). The threshold (:func:`outlier_threshold`) is the larger of
two quantiles, each at a per-recording false-rejection rate shared among the ``n`` frames
(Bonferroni): ``F(m, .)`` at ``OUTLIER_ALPHA`` (Gaussian noise) and ``F(d, .)`` at
``OUTLIER_ALPHA_HEAVY`` (heavier-tailed noise such as IGSIO's test model, a Gaussian
magnitude along a random direction, whose whitened residual is a 1-dimensional Gaussian
spread over ``m`` components: ``d = 1``). From ``TAIL_SHAPE_MIN_FRAMES`` frames on, ``d``
is estimated from the frames' quartiles (:func:`tail_shape`), so that a recording whose
noise looks Gaussian is tested nearly as such. Frames beyond the threshold are dropped and
the fit repeated, at most ``MAX_OUTLIER_FRACTION`` of the frames.

Two outliers can mask each other: each inflates the noise level the other is scaled by.
When no frame is beyond the threshold, the worst ``MASKING_GROUP`` frames are tested jointly
against a fit without them (their stacked prediction errors: ``F(g m, nu)``), at
``MASKING_SHARE`` of each budget shared among the ``C(n, g)`` groups of that size; the
one-frame tests have the rest, so that the per-recording budgets are unchanged. (It runs
from 11 frames on, where the leave-out test has two suspects; below, the one-frame tests
have the whole budgets.)

A gross outlier the threshold keeps still pulls the fit: below ``TAIL_SHAPE_MIN_FRAMES``
kept frames the threshold is the heavy tail's, and one of 4-6 sigma that the Gaussian test
would reject stays (a 10% share of them at 2.4 deg / 0.1 m put a 10-15 frame pivot at
1.4-1.5 times the Cramer-Rao bound of the clean frames). After the rejection, such frames
are down-weighted rather than dropped (:func:`_down_weighted`, up to
``LEAVE_ONE_OUT_MAX_FRAMES`` kept frames): a kept frame whose ``F_i`` lies beyond the
Gaussian model's per-frame ``OUTLIER_ALPHA`` quantile gets Tukey's taper from 1 there to 0
at the threshold (:func:`down_weights`), its information scaled by it, and the fit is
repeated. No frame is rejected by it, so the false-rejection rates are unchanged; a clean
Gaussian frame is touched with chance ``OUTLIER_ALPHA``, and the efficiency under clean
noise with it.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from math import comb

import numpy as np
from scipy import special

from acs_cli.core import lsq
from acs_cli.core.correlated import NOT_TESTED, CorrelatedErrors, covariance_with_correlated_errors
from acs_cli.core.se3 import FloatArray

NDArrayBool = np.ndarray

#: Chance that a clean recording with Gaussian noise loses a frame (see module doc).
OUTLIER_ALPHA = 0.01
#: Chance that a clean recording loses a frame under heavier-tailed noise: each pose's noise
#: a Gaussian magnitude along a uniformly random direction (IGSIO's test model; the
#: Mahalanobis distance is then ``m chi2(1)``, not ``chi2(m)``). Measured by
#: benchmarks/bench_outliers.py (docs/accuracy.md): clean recordings of 4 to 300 frames
#: lose a frame in at most 1% (Gaussian) and 4.2% (this model, at 15 and 30 frames) of trials.
OUTLIER_ALPHA_HEAVY = 0.02
#: Share of each false-rejection budget spent by the masking test of :func:`solve` (the worst
#: frames tested jointly) where it can run; the tests of one frame at a time have the rest.
MASKING_SHARE = 0.2
#: Largest share of frames that may be rejected as outliers.
MAX_OUTLIER_FRACTION = 0.3
#: Variance components are kept above this fraction of their natural scale (numerical floor).
_VARIANCE_FLOOR = 1e-8


def batched_inv3(S: FloatArray) -> FloatArray:
    """Inverses of ``(n, 3, 3)`` matrices by cofactors (fast for large ``n``)."""
    a, b, c = S[:, 0, 0], S[:, 0, 1], S[:, 0, 2]
    d, e, f = S[:, 1, 0], S[:, 1, 1], S[:, 1, 2]
    g, h, i = S[:, 2, 0], S[:, 2, 1], S[:, 2, 2]
    A = e * i - f * h
    B = -(d * i - f * g)
    Cc = d * h - e * g
    det = a * A + b * B + c * Cc
    out = np.empty_like(S)
    out[:, 0, 0], out[:, 1, 0], out[:, 2, 0] = A, B, Cc
    out[:, 0, 1] = -(b * i - c * h)
    out[:, 1, 1] = a * i - c * g
    out[:, 2, 1] = -(a * h - b * g)
    out[:, 0, 2] = b * f - c * e
    out[:, 1, 2] = -(a * f - c * d)
    out[:, 2, 2] = a * e - b * d
    return out / det[:, None, None]


def normal_equations(r: FloatArray, J: FloatArray, W: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``H = sum J_i^T W_i J_i`` ``(p, p)`` and ``g = sum J_i^T W_i r_i`` ``(p,)``."""
    p = J.shape[2]
    WJ = np.matmul(W, J).reshape(-1, p)
    Jf = J.reshape(-1, p)
    return Jf.T @ WJ, WJ.T @ r.reshape(-1)


def mahalanobis_sq(r: FloatArray, W: FloatArray) -> FloatArray:
    """``r_i^T W_i r_i`` for ``r`` ``(n, 3)`` and ``W`` ``(n, 3, 3)``."""
    return np.einsum("na,na->n", np.matmul(W, r[:, :, None])[:, :, 0], r)


def covariances(theta: FloatArray, L: FloatArray) -> FloatArray:
    """``Sigma_i = theta_t I + theta_r L_i`` ``(n, 3, 3)`` from lever shapes ``L`` ``(n, 3, 3)``."""
    S = theta[1] * L
    S[:, 0, 0] += theta[0]
    S[:, 1, 1] += theta[0]
    S[:, 2, 2] += theta[0]
    return S


def variance_component_information(
    theta: FloatArray, L: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Twice the Fisher information of the variance components, and the inverse covariances.

    ``F_kl = sum_i tr(S_i C_k S_i C_l)`` with ``S_i = Sigma_i^-1`` (:func:`covariances`),
    ``C_0 = I`` and ``C_1 = L_i``; the information about ``theta`` is ``F / 2``.

    Parameters
    ----------
    theta : ndarray, shape (2,)
        ``(theta_t, theta_r)``.
    L : ndarray, shape (n, 3, 3)
        Lever shapes.

    Returns
    -------
    F : ndarray, shape (2, 2)
    S : ndarray, shape (n, 3, 3)
        ``Sigma_i^-1``.
    """
    Si = batched_inv3(covariances(np.asarray(theta, dtype=float), L))
    SiL = np.matmul(Si, L)
    off = float(np.sum(Si * np.swapaxes(SiL, 1, 2)))
    F = np.array(
        [[float(np.sum(Si * Si)), off], [off, float(np.sum(SiL * np.swapaxes(SiL, 1, 2)))]]
    )
    return F, Si


def fit_variance_components(
    r: FloatArray,
    L: FloatArray,
    n_params: int = 0,
    theta0: FloatArray | None = None,
    iterations: int = 50,
) -> FloatArray:
    """Maximum-likelihood noise levels ``theta = (theta_t, theta_r)`` by Fisher scoring.

    The residual covariance is ``Sigma_i = theta_t I + theta_r L_i``: isotropic translation
    noise plus rotation noise seen through a lever arm.

    Parameters
    ----------
    r : ndarray, shape (n, 3)
        Residuals.
    L : ndarray, shape (n, 3, 3)
        Lever shapes (covariance of the residual per unit rotation variance).
    n_params : int
        Parameters fitted to the same residuals; the estimate is scaled by
        ``3n / (3n - n_params)`` to undo the usual downward bias of ML variances.
    theta0 : ndarray, shape (2,), optional
        Starting point (a previous estimate); equal shares of the residual power otherwise.

    Returns
    -------
    theta : ndarray, shape (2,)
        ``theta_t`` (units of ``r`` squared) and ``theta_r`` (radians squared).
    """
    n = r.shape[0]
    dof = 3 * n
    bias = dof / (dof - n_params) if dof > n_params else 1.0
    ms = float(np.mean(np.sum(r * r, axis=1))) + 1e-300
    trL = max(float(np.trace(L, axis1=1, axis2=2).mean()), 1e-300)
    # each component's natural scale (it alone explaining all residual power): the floor
    # is relative to it, so that it does not depend on the length unit
    floor = _VARIANCE_FLOOR * np.array([ms / 3.0, ms / trL])
    if theta0 is None:
        theta = np.array([ms / 6.0, ms / (2.0 * trL)])
    else:
        theta = np.maximum(np.asarray(theta0, dtype=float) / bias, 1e-300)
        iterations = min(iterations, 3)  # warm start: the caller iterates anyway
    for _ in range(iterations):
        F, Si = variance_component_information(theta, L)
        u = np.matmul(Si, r[:, :, None])[:, :, 0]
        q = np.array([np.sum(u * u), np.sum(np.matmul(L, u[:, :, None])[:, :, 0] * u)])
        try:
            new = np.linalg.solve(F, q)
        except np.linalg.LinAlgError:
            new = np.linalg.lstsq(F, q, rcond=None)[0]
        new = np.maximum(new, floor)
        done = np.max(np.abs(new - theta) / np.maximum(theta, 1e-300)) < 1e-4
        theta = new
        if done:
            break
    return np.asarray(theta * bias, dtype=float)


@dataclass
class LeastSquaresProblem:
    """A refined estimator's problem, as callables of the parameter vector ``x`` ``(p,)``.

    Attributes
    ----------
    residuals : (x, jac) -> (r (n, 3), J (n, 3, p) or None)
        Per-frame residuals and, when ``jac`` is true, their Jacobian (all frames; the
        solver masks).
    noise_shapes : x -> L (n, 3, 3)
        Lever shapes of the per-frame residuals: ``Sigma_i = theta_t I + theta_r L_i``.
    priors : x -> (r_p (m,), J_p (m, p), W_p (m, m)), optional
        Extra residual rows with a known information matrix (e.g. a joint from an
        earlier calibration with its covariance).
    retract : (x, dx) -> x, optional
        How a step is applied (default ``x + dx``); rotations use ``R Exp(dx)``.
    """

    residuals: Callable[[FloatArray, bool], tuple[FloatArray, FloatArray | None]]
    noise_shapes: Callable[[FloatArray], FloatArray]
    priors: Callable[[FloatArray], tuple[FloatArray, FloatArray, FloatArray]] | None = None
    retract: Callable[[FloatArray, FloatArray], FloatArray] | None = None


@dataclass
class LeastSquaresResult:
    """The solution of a :class:`LeastSquaresProblem`.

    Attributes
    ----------
    x : ndarray, shape (p,)
    covariance : ndarray, shape (p, p)
        Inverse of the final information matrix (noise levels estimated), grown where the
        frames' errors are correlated over time (:mod:`acs_cli.core.correlated`).
    theta : ndarray, shape (k,)
        Estimated variance components.
    residuals : ndarray, shape (n, 3)
        Residuals of every frame at ``x`` (rejected frames included).
    mahalanobis_sq : ndarray, shape (n,)
        ``r_i^T Sigma_i^{-1} r_i`` of every frame.
    inliers : ndarray of bool, shape (n,)
    iterations : int
    converged : bool
    """

    x: FloatArray
    covariance: FloatArray
    theta: FloatArray
    residuals: FloatArray
    mahalanobis_sq: FloatArray
    inliers: NDArrayBool
    iterations: int
    converged: bool
    information: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    #: what the test for errors correlated over time found; ``covariance`` includes it
    correlated: CorrelatedErrors = NOT_TESTED
    #: each frame's weight in ``[0, 1]`` (:func:`down_weights`; 1: full, empty: all 1)
    weights: FloatArray = field(default_factory=lambda: np.zeros(0))
    #: the covariance under independent noise (before the growth): what the motion's
    #: geometry determines, for the tests of degenerate motion (empty: ``covariance``)
    model_covariance: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def motion_covariance(self) -> FloatArray:
        """``model_covariance`` when there is one, else ``covariance``."""
        return self.model_covariance if self.model_covariance.size else self.covariance


def _rows(a: FloatArray, mask: NDArrayBool) -> FloatArray:
    """``a[mask]`` without a copy when every frame is kept."""
    return a if mask.all() else a[mask]


def f_isf(tail: float, d1: float, d2: float) -> float:
    """The upper ``tail`` quantile of Fisher's ``F(d1, d2)``, exact for tails of 1e-12 too.

    Through the regularised incomplete beta function: ``P(F > x) = I_w(d2/2, d1/2)`` with
    ``w = d2 / (d2 + d1 x)`` (scipy.special, as scipy.stats's ``f.isf``, without the
    ~0.6-1 s that importing scipy.stats adds to every command)."""
    w = float(special.betaincinv(d2 / 2.0, d1 / 2.0, tail))
    return d2 * (1.0 - w) / (d1 * w) if w > 0.0 else float("inf")


def outlier_threshold(
    n: int,
    dof: float,
    dim: int = 3,
    trimmed: float = 0.0,
    shape: float = 1.0,
    group: int = 1,
    share: float = 1.0,
) -> float:
    """Threshold on the studentised statistic ``F_i`` (module doc) of one of ``n`` frames.

    Parameters
    ----------
    n : int
        Frames of the recording (the false-rejection budgets are shared among them).
    dof : float
        Degrees of freedom of the noise level the statistic is scaled by: ``nu - m`` for a
        kept frame, ``nu`` for a frame predicted by a fit without it; ``inf`` for known
        noise levels (the statistic is then ``chi2(m) / m``).
    dim : int
        Dimension ``m`` of a frame's residual.
    trimmed : float
        Share of the frames, the largest residuals, left out of that noise level (the
        leave-out test of :func:`solve`). The noise level of the others is then too small,
        by the factor ``c = E[X | X < q] / E[X]`` with ``q`` the ``1 - trimmed`` quantile of
        the model's ``X``, and the threshold is divided by ``c`` (the consistency factor of a
        trimmed variance; ``X ~ chi2(m)`` Gaussian, ``chi2(shape)`` heavy-tailed).
    shape : float
        Degrees of freedom ``d`` in ``[1, m]`` of the heavy-tailed model, whose statistic
        is ``F(d, dof)`` (:func:`tail_shape`): 1 for noise along one random direction.
    group : int
        Frames ``g`` tested jointly (the masking test of :func:`solve`,
        :func:`_group_statistic`): ``F(g m, dof)``, heavy-tailed ``F(g d, dof)``, and the
        budget shared among the ``C(n, g)`` groups of that size (Bonferroni: any rule that
        picks the group to test is covered).
    share : float
        Share of each budget spent by this test (the rest by others of the recording).

    Returns
    -------
    float
        The larger of ``F(g m, dof)`` at tail probability ``share OUTLIER_ALPHA / C(n, g)``
        and ``F(g shape, dof)`` at ``share OUTLIER_ALPHA_HEAVY / C(n, g)``; ``inf`` when
        ``dof <= 0``.
    """
    if not dof > 0 or not share > 0:
        return float("inf")
    g = max(int(group), 1)
    tests = float(comb(max(n, g), g))
    tests /= share
    out = 0.0
    for d1, alpha in ((dim, OUTLIER_ALPHA), (min(max(shape, 1.0), dim), OUTLIER_ALPHA_HEAVY)):
        tail = alpha / tests
        dg = g * d1
        q = special.chdtri(dg, tail) / dg if np.isinf(dof) else f_isf(tail, dg, dof)
        if trimmed > 0.0:
            # E[X 1(X < q)] = d1 F_{d1+2}(q) for X ~ chi2(d1)
            keep = 1.0 - trimmed
            q /= special.chdtr(d1 + 2, special.chdtri(d1, trimmed)) / keep
        out = max(out, float(q))
    return out


@dataclass
class _Studentized:
    """Studentised residuals of a fit (module doc): ``stat`` ``(n,)`` is ``F_i`` for a kept
    frame (noise level with ``dof_kept`` degrees of freedom) and, for a dropped frame, its
    prediction error by the fit ``(T_i / m) / (S / nu)`` (``dof_dropped = nu``)."""

    stat: FloatArray
    dof_kept: float
    dof_dropped: float
    dim: int
    shape: float = 1.0


#: Fewest degrees of freedom of the noise level a frame is tested against. With fewer (a
#: pivot of 4 frames: 12 residuals, 6 unknowns, 2 noise levels, 3 for the frame left out:
#: 2) the fitted ratio of the noise levels can put all the residual power in one frame
#: (a noise level at its floor); the test then rejected a clean frame in 8% of recordings.
MIN_TEST_DOF = 3
#: Relative ridge on ``I -+ H_ii`` (a frame that alone fixes a parameter has leverage 1).
_LEVERAGE_RIDGE = 1e-9


#: Fewest kept frames from which :func:`tail_shape` is estimated (fewer: the heavy-tailed
#: model's 1 degree of freedom, the most cautious).
TAIL_SHAPE_MIN_FRAMES = 50
#: Subtracted from the estimated degrees of freedom (a cautious estimate: its spread is
#: about 0.3 at 100 frames, and IGSIO's noise has a heavier tail than the chi-square of the
#: same quartiles).
TAIL_SHAPE_MARGIN = 0.9


def tail_shape(T: FloatArray, dim: int) -> float:
    """Degrees of freedom ``d`` in ``[1, dim]`` of the chi-square that the frames' squared
    studentised distances ``T`` ``(k,)`` follow, from their lower quartile over their
    median (robust to the largest quarter being outliers).

    Gaussian noise gives ``d = dim``; noise along one random direction (IGSIO's model)
    ``d = 1``: the same variance, a much heavier tail. Testing against ``chi2(dim)`` alone
    rejects a clean frame of 50% of such 100-frame recordings; against ``chi2(1)`` alone,
    gross outliers of 5-6 sigma go unnoticed when the noise is Gaussian (their error at
    2.4 deg / 0.1 m was 1.5 times the bound). 1 when fewer than ``TAIL_SHAPE_MIN_FRAMES``.
    """
    if T.size < TAIL_SHAPE_MIN_FRAMES or dim <= 1:
        return 1.0
    q50, q75 = np.quantile(T, [0.5, 0.75])
    if not q50 > 0:
        return 1.0
    d = np.linspace(1.0, dim, 41)
    ratio = special.chdtri(d, 0.25) / special.chdtri(d, 0.5)  # quartile / median, decreasing
    estimate = float(np.interp(-q75 / q50, -ratio, d))
    return max(estimate - TAIL_SHAPE_MARGIN, 1.0)


def _information(
    problem: LeastSquaresProblem,
    x: FloatArray,
    r: FloatArray,
    J: FloatArray,
    W: FloatArray,
    mask: NDArrayBool,
) -> FloatArray:
    """``sum J_i^T W_i J_i`` over the kept frames plus the prior rows' ``J_p^T W_p J_p``."""
    H, _ = normal_equations(_rows(r, mask), _rows(J, mask), _rows(W, mask))
    if problem.priors is not None:
        _, Jp, Wp = problem.priors(x)
        H = H + Jp.T @ Wp @ Jp
    return np.asarray(H)


def _studentize(
    problem: LeastSquaresProblem, fit: _Fit, mask: NDArrayBool, known_scale: bool
) -> _Studentized:
    """Studentised residuals of every frame at ``fit`` (kept frames ``mask``); with
    ``known_scale`` (noise levels given) the scale is not estimated (``dof = inf``)."""
    r, J = _with_jacobian(problem, fit.x)
    U = whitener(fit.W)
    e = np.einsum("nij,nj->ni", U, r)
    G = np.matmul(U, J)
    Hinv = np.linalg.pinv(_information(problem, fit.x, r, J, fit.W, mask), hermitian=True)
    Hii = np.matmul(G @ Hinv, np.swapaxes(G, 1, 2))  # (n, 3, 3) blocks of the hat matrix
    # residual components that are not identically zero (e.g. 2 of 3 for a hinge axis)
    dim = max(int(np.count_nonzero(np.any(_rows(r, mask) != 0.0, axis=0))), 1)
    sign = np.where(mask, -1.0, 1.0)[:, None, None]
    M = np.eye(3) + sign * Hii + _LEVERAGE_RIDGE * np.eye(3)
    T = mahalanobis_sq(e, batched_inv3(M))
    if known_scale:
        return _Studentized(T / dim, np.inf, np.inf, dim)
    # the frames' share of the fitted parameters, sum_i tr(H_ii) (priors take the rest),
    # and one more for the ratio of the two noise levels, fitted to the same residuals
    p_eff = float(np.trace(_rows(Hii, mask), axis1=1, axis2=2).sum())
    nu = dim * int(mask.sum()) - p_eff - (fit.theta.size - 1)
    S = float(np.sum(_rows(e, mask) ** 2))
    if nu - dim < MIN_TEST_DOF or not S > 0:
        return _Studentized(np.zeros(r.shape[0]), 0.0, 0.0, dim)
    kept_scale = np.maximum(S - T, 1e-12 * S) / (nu - dim)
    stat = T / dim / np.where(mask, kept_scale, S / nu)
    return _Studentized(stat, nu - dim, nu, dim, tail_shape(_rows(T, mask), dim))


def _with_jacobian(problem: LeastSquaresProblem, x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Residuals and their Jacobian (which a problem must give when asked)."""
    r, J = problem.residuals(x, True)
    if J is None:
        raise RuntimeError("the problem gave no Jacobian when asked for one")
    return r, J


#: Points whose residuals :func:`_memoised` remembers (the engine revisits its best point).
_MEMO_SIZE = 4


def _memoised(problem: LeastSquaresProblem) -> LeastSquaresProblem:
    """The problem with its residuals at the last few ``x`` remembered (they are asked for
    several times at one point: residuals, Jacobian, weights)."""
    raw = problem.residuals
    memo: OrderedDict[bytes, tuple[FloatArray, FloatArray | None]] = OrderedDict()

    def cached(x: FloatArray, jac: bool) -> tuple[FloatArray, FloatArray | None]:
        key = x.tobytes()
        hit = memo.get(key)
        if hit is None or (jac and hit[1] is None):
            hit = raw(x, jac)
            memo[key] = hit
            if len(memo) > _MEMO_SIZE:
                memo.popitem(last=False)
        else:
            memo.move_to_end(key)
        return hit[0], (hit[1] if jac else None)

    return LeastSquaresProblem(cached, problem.noise_shapes, problem.priors, problem.retract)


def whitener(W: FloatArray) -> FloatArray:
    """``U_i = chol(W_i)^T`` ``(n, 3, 3)`` for information matrices ``W_i`` ``(n, 3, 3)``:
    ``|U_i r_i|^2 = r_i^T W_i r_i`` (one batched Cholesky, no loop over frames)."""
    return np.swapaxes(np.linalg.cholesky(W), -1, -2)


def _whiten_prior(Wp: FloatArray, a: FloatArray) -> FloatArray:
    """``chol(W_p)^T a`` for prior rows ``a`` ``(m,)`` or ``(m, p)``; ``W_p`` ``(m, m)``."""
    return np.asarray(np.linalg.cholesky(Wp).T @ a)


def _whitened(
    problem: LeastSquaresProblem, mask: NDArrayBool, W: FloatArray
) -> tuple[Callable[[FloatArray], FloatArray], Callable[[FloatArray], FloatArray]]:
    """Residuals ``(3 k + m,)`` and Jacobian ``(3 k + m, p)`` for the engine, with the
    weights held: the ``k`` kept frames' ``chol(W_i)^T r_i`` and the prior rows
    ``chol(W_p)^T r_p``."""
    U = whitener(_rows(W, mask))

    def fun(x: FloatArray) -> FloatArray:
        r, _ = problem.residuals(x, False)
        out = np.einsum("nij,nj->ni", U, _rows(r, mask)).reshape(-1)
        if problem.priors is not None:
            rp, _, Wp = problem.priors(x)
            out = np.concatenate([out, _whiten_prior(Wp, rp)])
        return out

    def jac(x: FloatArray) -> FloatArray:
        _, J = _with_jacobian(problem, x)
        out = np.matmul(U, _rows(J, mask)).reshape(-1, J.shape[2])
        if problem.priors is not None:
            _, Jp, Wp = problem.priors(x)
            out = np.concatenate([out, _whiten_prior(Wp, Jp)])
        return out

    return fun, jac


@dataclass
class _Fit:
    """State of one fit on a fixed set of frames."""

    x: FloatArray
    theta: FloatArray
    W: FloatArray
    converged: bool
    iterations: int


#: Residual evaluations allowed to one weighted solve (weights held) of :func:`_fit`.
_INNER_MAX_NFEV = 50
#: Relative tolerances of that solve (cost decrease, step): near machine precision, so that
#: fits started from different points end at the same place.
_INNER_TOL = 1e-14


def _fit(
    problem: LeastSquaresProblem,
    x0: FloatArray,
    theta0: FloatArray | None,
    mask: NDArrayBool,
    fixed_theta: bool,
    max_outer: int,
    frame_weights: FloatArray | None = None,
) -> _Fit:
    """Alternate the weighted least-squares solve (weights held, :func:`lsq.solve`) and
    the ML noise levels (:func:`fit_variance_components`) until both settle.
    ``frame_weights`` ``(n,)`` in ``[0, 1]`` scale each frame's information (the
    down-weighting of :func:`solve`); its noise levels see the residuals so scaled."""
    problem = _memoised(problem)
    x = np.asarray(x0, dtype=float).copy()
    p = x.size

    def weights(x: FloatArray, th: FloatArray | None) -> tuple[FloatArray, FloatArray]:
        L = problem.noise_shapes(x)
        if not fixed_theta:
            r, _ = problem.residuals(x, False)
            if frame_weights is not None:
                r = r * np.sqrt(frame_weights)[:, None]
            th = fit_variance_components(_rows(r, mask), _rows(L, mask), p, th)
        if th is None:  # pragma: no cover - fixed_theta is False whenever th is None
            raise RuntimeError("noise levels neither given nor fitted")
        W = batched_inv3(covariances(th, L))
        return th, W if frame_weights is None else W * frame_weights[:, None, None]

    th, W = weights(x, theta0)
    converged = False
    it = 0
    for _outer in range(max_outer):
        it += 1
        x_start = x.copy()
        fun, jac = _whitened(problem, mask, W)
        # each outer iteration starts at the current point: the retraction is re-centred
        # there, so one engine round suffices
        sol = lsq.solve(
            fun,
            x,
            jac=jac,
            retract=problem.retract,
            method="normal",
            ftol=_INNER_TOL,
            xtol=_INNER_TOL,
            gtol=_INNER_TOL,
            max_nfev=_INNER_MAX_NFEV,
            max_rounds=1,
            final_jac=False,
        )
        if np.all(np.isfinite(sol.x)):
            x = sol.x
        th_old = th
        th, W = weights(x, th)
        moved = float(np.linalg.norm(x - x_start)) / (1.0 + float(np.linalg.norm(x)))
        change = float(np.max(np.abs(th - th_old) / np.maximum(th_old, 1e-300)))
        if moved < 1e-8 and change < 1e-3:
            converged = True
            break
    return _Fit(x, th, W, converged, it)


#: Up to this many kept frames, the worst frames are also tested against a fit without them
#: (leave-out), so that outliers cannot hide by inflating the fitted noise levels.
LEAVE_ONE_OUT_MAX_FRAMES = 2000
#: Share of the kept frames tested together in the leave-out test (when two or more).
LEAVE_OUT_SHARE = 0.1


#: Frames tested jointly by the masking test of :func:`solve` (the worst of the kept frames).
MASKING_GROUP = 2


def _group_statistic(
    problem: LeastSquaresProblem, fit: _Fit, mask: NDArrayBool, group: np.ndarray
) -> tuple[float, float, int]:
    """Joint studentised statistic of the frames ``group`` ``(g,)``, left out of ``mask``,
    predicted by ``fit`` (a fit of the kept frames): ``(T_G / (g m)) / (S / nu)`` with
    ``T_G = e_G^T (I + H_GG)^{-1} e_G`` over their stacked whitened residuals ``e_G``
    ``(3 g,)`` and ``H_GG`` their ``3 g x 3 g`` block of the (extended) hat matrix, cross
    terms included. ``F(g m, nu)`` under Gaussian noise for a linear model. Returns the
    statistic, ``nu`` (0 when too few degrees of freedom) and ``m``."""
    r, J = _with_jacobian(problem, fit.x)
    U = whitener(fit.W)
    e = np.einsum("nij,nj->ni", U, r)
    G = np.matmul(U, J)
    Hinv = np.linalg.pinv(_information(problem, fit.x, r, J, fit.W, mask), hermitian=True)
    Gk = _rows(G, mask)
    p_eff = float(np.einsum("nij,jk,nik->", Gk, Hinv, Gk))
    dim = max(int(np.count_nonzero(np.any(_rows(r, mask) != 0.0, axis=0))), 1)
    nu = dim * int(mask.sum()) - p_eff - (fit.theta.size - 1)
    S = float(np.sum(_rows(e, mask) ** 2))
    if nu < MIN_TEST_DOF or not S > 0:
        return 0.0, 0.0, dim
    Gg = G[group].reshape(-1, G.shape[2])
    eg = e[group].reshape(-1)
    A = np.eye(eg.size) * (1.0 + _LEVERAGE_RIDGE) + Gg @ Hinv @ Gg.T
    T = float(eg @ np.linalg.solve(A, eg))
    return T / (len(group) * dim) / (S / nu), nu, dim


_WEIGHT_FLOOR = 1e-6
#: Rounds of :func:`_down_weighted` (weights from the previous fit).
DOWN_WEIGHT_ROUNDS = 4


def down_weights(stat: FloatArray, lower: float, upper: float) -> FloatArray:
    """Weights ``(n,)`` of frames by their studentised statistic ``stat`` ``(n,)``: 1 up to
    ``lower``, Tukey's taper ``(1 - u^2)^2`` with ``u = (F - lower) / (upper - lower)`` on
    to ``upper`` (the rejection threshold), 0 beyond."""
    if not upper > lower:
        return np.ones_like(stat)
    u = np.clip((stat - lower) / (upper - lower), 0.0, 1.0)
    # floored: a frame's information stays positive definite (whitened by Cholesky)
    return np.maximum((1.0 - u**2) ** 2, _WEIGHT_FLOOR)


def _noise_information(
    problem: LeastSquaresProblem, x: FloatArray, theta: FloatArray
) -> FloatArray:
    """``Sigma_i^{-1}`` ``(n, 3, 3)`` at ``x`` from the noise levels ``theta`` alone (no
    frame's down-weighting)."""
    return batched_inv3(covariances(theta, problem.noise_shapes(x)))


def _down_weighted(
    problem: LeastSquaresProblem,
    fit: _Fit,
    mask: NDArrayBool,
    n: int,
    share: float,
    max_outer: int,
) -> tuple[_Fit, FloatArray, int]:
    """Down-weight the kept frames the Gaussian test would doubt but the rejection
    threshold keeps (module doc; below ``TAIL_SHAPE_MIN_FRAMES`` frames it is the heavy
    tail's, and a gross outlier of 4-6 sigma stays).

    A kept frame whose statistic is beyond the Gaussian model's per-frame
    ``OUTLIER_ALPHA`` quantile gets the weight :func:`down_weights` (to 0 at the
    threshold). Clean Gaussian frames are touched in about ``OUTLIER_ALPHA`` of cases; no
    frame is rejected by it (``mask`` unchanged). Up to ``DOWN_WEIGHT_ROUNDS`` rounds, each
    from the previous fit's statistics; a weight never grows back. Returns the fit, the
    weights ``(n,)`` and the iterations."""
    w = np.ones(mask.size)
    if int(mask.sum()) > LEAVE_ONE_OUT_MAX_FRAMES:
        return fit, w, 0
    extra = 0
    base = fit
    for _round in range(DOWN_WEIGHT_ROUNDS):
        plain = _Fit(fit.x, fit.theta, _noise_information(problem, fit.x, fit.theta), True, 0)
        st = _studentize(problem, plain, mask, False)
        if not st.dof_kept > 0:
            return base, np.ones(mask.size), extra
        upper = outlier_threshold(n, st.dof_kept, st.dim, shape=st.shape, share=share)
        lower = f_isf(OUTLIER_ALPHA, st.dim, st.dof_kept)
        # a weight never grows back: the rounds cannot cycle on a frame at the lower level
        w_new = np.minimum(w, np.where(mask, down_weights(st.stat, lower, upper), 1.0))
        if np.all(w_new == 1.0) and _round == 0:
            return base, w, extra
        if np.max(np.abs(w_new - w)) < 1e-3:
            break
        w = w_new
        fit = _fit(problem, fit.x, fit.theta, mask, False, max_outer, frame_weights=w)
        extra += fit.iterations
    return fit, w, extra


def negative_log_likelihood(
    problem: LeastSquaresProblem, x: FloatArray, W: FloatArray, mask: NDArrayBool
) -> float:
    """``0.5 sum_i (r_i^T W_i r_i - log det W_i)`` over the kept frames, plus the prior
    rows' ``0.5 r_p^T W_p r_p``: the Gaussian negative log-likelihood (up to a constant) of
    ``x`` with the information matrices ``W`` ``(n, 3, 3)`` (its noise levels)."""
    r, _ = problem.residuals(x, False)
    Wk = _rows(W, mask)
    _, logdet = np.linalg.slogdet(Wk)
    out = 0.5 * float(np.sum(mahalanobis_sq(_rows(r, mask), Wk)) - np.sum(logdet))
    if problem.priors is not None:
        rp, _, Wp = problem.priors(x)
        out += 0.5 * float(rp @ Wp @ rp)
    return out


def solve(
    problem: LeastSquaresProblem,
    x0: FloatArray,
    *,
    alternatives: Sequence[FloatArray] = (),
    theta: FloatArray | None = None,
    reject_outliers: bool = True,
    max_outer: int = 30,
    max_batch_rounds: int = 8,
) -> LeastSquaresResult:
    """Iteratively reweighted Levenberg-Marquardt with variance-component estimation.

    Outlier rejection (when ``reject_outliers``): after each fit, every frame whose
    studentised residual (module doc) is beyond :func:`outlier_threshold` is dropped at once
    and the fit repeated. When none is beyond it, the worst ``LEAVE_OUT_SHARE`` of the frames
    are predicted by a fit of the others and tested the same way (for at most
    ``LEAVE_ONE_OUT_MAX_FRAMES`` frames): outliers inflate the fitted noise levels and can
    hide each other. When that rejects none, the worst ``MASKING_GROUP`` are tested jointly
    (:func:`_group_statistic`, ``group`` of :func:`outlier_threshold`) and dropped together
    if beyond. At most ``MAX_OUTLIER_FRACTION`` of the frames are dropped.

    Parameters
    ----------
    problem : LeastSquaresProblem
    x0 : ndarray, shape (p,)
        Initial parameters.
    alternatives : sequence of ndarray, shape (p,)
        Other starting points. Each start is fitted on every frame, and the fit of the
        smallest :func:`negative_log_likelihood` goes on to the outlier rejection: a
        guard against a start in the basin of a wrong minimum.
    theta : ndarray, shape (2,), optional
        Fixed noise levels ``(theta_t, theta_r)``; estimated when ``None``.
    reject_outliers : bool
    """
    r0, _ = problem.residuals(np.asarray(x0, dtype=float), False)
    n = r0.shape[0]
    mask = np.ones(n, dtype=bool)
    fixed_theta = theta is not None
    th0 = None if theta is None else np.asarray(theta, dtype=float)
    fit = _fit(problem, x0, th0, mask, fixed_theta, max_outer)
    iterations = fit.iterations
    if alternatives:
        best = negative_log_likelihood(problem, fit.x, fit.W, mask)
        for start in alternatives:
            other = _fit(problem, np.asarray(start, dtype=float), th0, mask, fixed_theta, max_outer)
            iterations += other.iterations
            value = negative_log_likelihood(problem, other.x, other.W, mask)
            if np.isfinite(value) and value < best:
                fit, best = other, value
    max_reject = int(np.floor(MAX_OUTLIER_FRACTION * n))
    # the masking test's share of the budgets, where it can run (module doc)
    masking = (
        not fixed_theta
        and max_reject >= MASKING_GROUP
        and MASKING_GROUP <= np.ceil(LEAVE_OUT_SHARE * n)
        and n <= LEAVE_ONE_OUT_MAX_FRAMES
    )
    single = 1.0 - MASKING_SHARE if masking else 1.0
    batch_rounds = 0
    while reject_outliers:
        room = max_reject - int((~mask).sum())
        if room <= 0:
            break
        st = _studentize(problem, fit, mask, fixed_theta)
        threshold = outlier_threshold(n, st.dof_kept, st.dim, shape=st.shape, share=single)
        candidates = np.flatnonzero(mask & (st.stat > threshold))
        if candidates.size and batch_rounds < max_batch_rounds:
            batch_rounds += 1
            mask[candidates[np.argsort(st.stat[candidates])[::-1][:room]]] = False
            fit = _fit(problem, fit.x, fit.theta, mask, fixed_theta, max_outer)
            iterations += fit.iterations
            continue
        if mask.sum() > LEAVE_ONE_OUT_MAX_FRAMES or fixed_theta:
            break
        # group deletion: the worst ~10% of the kept frames, each predicted by a fit of the
        # others (outliers inflate the fitted noise and so hide each other). For one frame
        # this is the studentised test above (which already leaves the frame out), so it
        # needs two; each suspect's noise level then lacks the other suspects, the largest
        # residuals, which the threshold allows for (trimmed share).
        kept = np.flatnonzero(mask)
        k = min(room, int(np.ceil(LEAVE_OUT_SHARE * kept.size)))
        if k < 2:
            break
        suspects = kept[np.argsort(st.stat[kept])[::-1][:k]]
        trial_mask = mask.copy()
        trial_mask[suspects] = False
        loo = _fit(problem, fit.x, fit.theta, trial_mask, fixed_theta, max_outer)
        iterations += loo.iterations
        st_loo = _studentize(problem, loo, trial_mask, fixed_theta)
        trimmed = (k - 1) / kept.size
        threshold = outlier_threshold(
            n, st_loo.dof_dropped, st_loo.dim, trimmed, st.shape, share=single
        )
        out = suspects[st_loo.stat[suspects] > threshold]
        if out.size == 0:
            # masking: two outliers each inflate the noise level the other is scaled by,
            # and the leave-out test above allows for clean frames among its suspects
            # (trimmed share). The worst MASKING_GROUP frames are tested jointly against a
            # fit without just them, the budget shared among all groups of that size.
            group = suspects[:MASKING_GROUP]
            if not masking or group.size < MASKING_GROUP or room < MASKING_GROUP:
                break
            if k == MASKING_GROUP:  # the leave-out fit above is without just them
                pair = loo
            else:
                trial_mask = mask.copy()
                trial_mask[group] = False
                pair = _fit(problem, fit.x, fit.theta, trial_mask, fixed_theta, max_outer)
                iterations += pair.iterations
            stat, dof, dim = _group_statistic(problem, pair, trial_mask, group)
            limit = outlier_threshold(
                n, dof, dim, shape=st.shape, group=group.size, share=MASKING_SHARE
            )
            if not stat > limit:
                break
            mask = trial_mask
            fit = pair
            continue
        mask[out] = False
        fit = (
            loo if out.size == k else _fit(problem, loo.x, loo.theta, mask, fixed_theta, max_outer)
        )
    frame_weights: FloatArray = np.ones(n)
    if reject_outliers and not fixed_theta:
        fit, frame_weights, extra = _down_weighted(problem, fit, mask, n, single, max_outer)
        iterations += extra
    x, th, W = fit.x, fit.theta, fit.W
    r, J = _with_jacobian(problem, x)
    H = _information(problem, x, r, J, W, mask)
    cov = np.linalg.pinv(H, rcond=1e-14, hermitian=True)
    # errors correlated over time: the block sandwich on the kept frames' scores J^T W r
    scores = np.einsum("nai,nab,nb->ni", _rows(J, mask), _rows(W, mask), _rows(r, mask))
    grown, found = covariance_with_correlated_errors(cov, scores)
    return LeastSquaresResult(
        x=x,
        covariance=grown,
        model_covariance=cov,
        correlated=found,
        theta=np.asarray(th, dtype=float),
        residuals=r,
        # against the noise levels alone (a down-weighted frame's residual is not smaller)
        mahalanobis_sq=mahalanobis_sq(r, _noise_information(problem, x, th)),
        inliers=mask,
        weights=frame_weights,
        iterations=iterations,
        converged=fit.converged,
        information=H,
    )
