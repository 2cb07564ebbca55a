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

Gross outliers are rejected: after convergence, frames whose Mahalanobis distance
``r_i^T Sigma_i^{-1} r_i`` exceeds the chi-square(3) quantile with tail probability
``OUTLIER_ALPHA / n`` (so that a clean recording of any length loses a frame with
probability about ``OUTLIER_ALPHA``) are dropped and the fit repeated, at most
``MAX_OUTLIER_FRACTION`` of the frames.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from acs_cli.core import lsq
from acs_cli.core.se3 import FloatArray

NDArrayBool = np.ndarray

#: Chance that a clean recording loses one frame to outlier rejection (see module doc).
OUTLIER_ALPHA = 0.01
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
        Si = batched_inv3(covariances(theta, L))
        SiL = np.matmul(Si, L)
        # Fisher information F_kl = sum_i tr(Si C_k Si C_l) with C_0 = I, C_1 = L
        F = np.array(
            [
                [np.sum(Si * Si), np.sum(Si * np.swapaxes(SiL, 1, 2))],
                [0.0, np.sum(SiL * np.swapaxes(SiL, 1, 2))],
            ]
        )
        F[1, 0] = F[0, 1]
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
        Inverse of the final information matrix (noise levels estimated).
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


def _rows(a: FloatArray, mask: NDArrayBool) -> FloatArray:
    """``a[mask]`` without a copy when every frame is kept."""
    return a if mask.all() else a[mask]


def outlier_threshold(n: int) -> float:
    """Squared Mahalanobis distance above which one of ``n`` frames is an outlier."""
    from scipy.stats import chi2  # lazily: importing scipy.stats costs ~0.6 s a command

    return float(chi2.isf(OUTLIER_ALPHA / max(n, 1), 3))


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
) -> _Fit:
    """Alternate the weighted least-squares solve (weights held, :func:`lsq.solve`) and
    the ML noise levels (:func:`fit_variance_components`) until both settle."""
    problem = _memoised(problem)
    x = np.asarray(x0, dtype=float).copy()
    p = x.size

    def weights(x: FloatArray, th: FloatArray | None) -> tuple[FloatArray, FloatArray]:
        L = problem.noise_shapes(x)
        if not fixed_theta:
            r, _ = problem.residuals(x, False)
            th = fit_variance_components(_rows(r, mask), _rows(L, mask), p, th)
        if th is None:  # pragma: no cover - fixed_theta is False whenever th is None
            raise RuntimeError("noise levels neither given nor fitted")
        return th, batched_inv3(covariances(th, L))

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
#: Share of the kept frames (at least one) tested together in the leave-out test.
LEAVE_OUT_SHARE = 0.1
#: The leave-one-out test removes the largest residual from the noise fit, which biases the
#: fitted noise down; the worst frame is rejected only beyond this many times the threshold.
#: Outliers that hide behind inflated noise levels exceed it by far.
LEAVE_ONE_OUT_FACTOR = 2.5  # calibrated: <= 1% of clean 30-frame recordings lose a frame


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

    Outlier rejection (when ``reject_outliers``): after each fit, every frame beyond
    :func:`outlier_threshold` is dropped at once and the fit repeated. When none is beyond
    it, the worst ``LEAVE_OUT_SHARE`` of the frames are tested against a fit of the others
    (for at most ``LEAVE_ONE_OUT_MAX_FRAMES`` frames): outliers inflate the fitted noise
    levels and can hide each other. At most ``MAX_OUTLIER_FRACTION`` of the frames are dropped.

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
    threshold = outlier_threshold(n)
    batch_rounds = 0
    while reject_outliers:
        room = max_reject - int((~mask).sum())
        if room <= 0:
            break
        r, _ = problem.residuals(fit.x, False)
        d2 = mahalanobis_sq(r, fit.W)
        candidates = np.flatnonzero(mask & (d2 > threshold))
        if candidates.size and batch_rounds < max_batch_rounds:
            batch_rounds += 1
            mask[candidates[np.argsort(d2[candidates])[::-1][:room]]] = False
            fit = _fit(problem, fit.x, fit.theta, mask, fixed_theta, max_outer)
            iterations += fit.iterations
            continue
        if mask.sum() > LEAVE_ONE_OUT_MAX_FRAMES or fixed_theta:
            break
        # group deletion: the worst ~10% of the kept frames, each tested against a fit of
        # the others (outliers inflate the fitted noise and so hide each other)
        kept = np.flatnonzero(mask)
        k = min(room, max(1, int(np.ceil(LEAVE_OUT_SHARE * kept.size))))
        suspects = kept[np.argsort(d2[kept])[::-1][:k]]
        trial_mask = mask.copy()
        trial_mask[suspects] = False
        loo = _fit(problem, fit.x, fit.theta, trial_mask, fixed_theta, max_outer)
        iterations += loo.iterations
        r_loo, _ = problem.residuals(loo.x, False)
        d2_loo = mahalanobis_sq(r_loo[suspects], loo.W[suspects])
        out = suspects[d2_loo > LEAVE_ONE_OUT_FACTOR * threshold]
        if out.size == 0:
            break
        mask[out] = False
        fit = (
            loo if out.size == k else _fit(problem, loo.x, loo.theta, mask, fixed_theta, max_outer)
        )
    x, th, W = fit.x, fit.theta, fit.W
    r, J = _with_jacobian(problem, x)
    H, _ = normal_equations(_rows(r, mask), _rows(J, mask), _rows(W, mask))
    if problem.priors is not None:
        _, Jp, Wp = problem.priors(x)
        H = H + Jp.T @ Wp @ Jp
    cov = np.linalg.pinv(H, rcond=1e-14, hermitian=True)
    return LeastSquaresResult(
        x=x,
        covariance=cov,
        theta=np.asarray(th, dtype=float),
        residuals=r,
        mahalanobis_sq=mahalanobis_sq(r, W),
        inliers=mask,
        iterations=iterations,
        converged=fit.converged,
        information=H,
    )
