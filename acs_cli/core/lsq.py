"""The one nonlinear least-squares engine of every solver: ``scipy.optimize.least_squares``.

Every refined estimator (:mod:`acs_cli.core.estimation`, hence the joint and relative-pose
estimators), both bundle adjustments (:mod:`acs_cli.core.bundle`) and the paper's
Algorithms III/IV (:mod:`acs_cli.core.relpose`) minimise ``|f(x)|^2`` through
:func:`solve`. Callers whiten their residuals themselves (``f`` is already divided by its
noise), so that the minimum is the maximum-likelihood estimate.

Jacobians are analytic: ``jac(x)`` gives ``df/dx`` as a dense ``(m, p)`` array (small
problems: Levenberg-Marquardt, MINPACK) or a ``scipy.sparse`` matrix (bundles: a trust
region with LSMR, which never forms a dense ``m x p`` array). Without ``jac``, scipy
differences ``f`` numerically, all columns in one call when the caller gives a sparsity
pattern (``jac_sparsity``).

Manifolds. Rotations are updated as ``R Exp(dx)``: with ``retract`` given, the solver
works on the increment ``d`` around a centre ``c`` (``x = retract(c, d)``, ``d = 0`` at
the start) and ``jac(x)`` is the derivative with respect to a further increment at ``x``,
``d f(retract(x, e)) / de`` at ``e = 0`` (what the estimators' Jacobians give). Within one
call that is the Jacobian with respect to ``d`` up to a factor ``I + O(|d|)`` (the right
Jacobian of SO(3)), which leaves the stationary points exact and only slows convergence
when ``d`` is large; the solver then re-centres (``c <- retract(c, d)``) and runs again,
at most ``max_rounds`` times.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import sparse

from acs_cli.core.se3 import FloatArray

#: A Jacobian as the caller gives it: dense ``(m, p)`` or a ``scipy.sparse`` matrix.
Jacobian = Any
#: Re-centre when the increment's largest entry exceeds this (rotation increments in
#: radians: the Jacobian is then off by more than about ``|d| / 2``, 0.5%).
RECENTRE_STEP = 1e-2
#: A sparse Jacobian of at most this many entries (rows x columns) is solved densely (MINPACK);
#: beyond, by the trust-region method with LSMR steps, which never forms the dense array.
DENSE_LIMIT = 1_000_000
#: Relative tolerance of the LSMR steps of the trust-region method (sparse Jacobians).
LSMR_TOL = 1e-12


@dataclass(frozen=True)
class Solution:
    """Result of :func:`solve`.

    Attributes
    ----------
    x : ndarray, shape (p,)
        The minimiser (a point of the manifold when ``retract`` was given).
    fun : ndarray, shape (m,)
        Residuals ``f(x)``.
    jac : ndarray (m, p), scipy.sparse matrix or None
        Jacobian at ``x`` (with respect to an increment at ``x`` under ``retract``; None
        when not asked for, see ``final_jac``).
    cost : float
        ``|f(x)|^2 / 2``.
    success : bool
        scipy's convergence flag (a tolerance met, not the evaluation limit).
    nfev : int
        Residual evaluations over all rounds.
    """

    x: FloatArray
    fun: FloatArray
    jac: Jacobian
    cost: float
    success: bool
    nfev: int


class _Chart:
    """``f`` and ``jac`` of the increment ``d`` at a centre ``c`` (``x = retract(c, d)``),
    with the last point remembered (scipy asks ``f`` and ``jac`` at the same ``d``)."""

    def __init__(
        self,
        fun: Callable[[FloatArray], FloatArray],
        jac: Callable[[FloatArray], Jacobian] | None,
        retract: Callable[[FloatArray, FloatArray], FloatArray],
        centre: FloatArray,
    ) -> None:
        self.fun, self.jac, self.retract, self.centre = fun, jac, retract, centre
        self._key: bytes | None = None
        self._x = centre

    def point(self, d: FloatArray) -> FloatArray:
        key = d.tobytes()
        if key != self._key:
            self._key, self._x = key, self.retract(self.centre, d)
        return self._x

    def f(self, d: FloatArray) -> FloatArray:
        return self.fun(self.point(d))

    def j(self, d: FloatArray) -> Jacobian:
        if self.jac is None:
            raise ValueError("no analytic Jacobian was given: scipy differences f instead")
        return self.jac(self.point(d))


def solve(
    fun: Callable[[FloatArray], FloatArray],
    x0: FloatArray,
    *,
    jac: Callable[[FloatArray], Jacobian] | None = None,
    jac_sparsity: Any = None,
    retract: Callable[[FloatArray, FloatArray], FloatArray] | None = None,
    method: str | None = None,
    x_scale: str | float | FloatArray = "jac",
    ftol: float = 1e-12,
    xtol: float = 1e-12,
    gtol: float = 1e-12,
    max_nfev: int | None = None,
    max_rounds: int = 4,
    final_jac: bool = True,
) -> Solution:
    """Minimise ``|fun(x)|^2`` with ``scipy.optimize.least_squares``.

    Parameters
    ----------
    fun : x -> ndarray, shape (m,)
        Whitened residuals.
    x0 : ndarray, shape (p,)
        Starting point.
    jac : x -> ndarray (m, p) or scipy.sparse matrix, optional
        Analytic Jacobian (with respect to an increment at ``x`` under ``retract``).
        Numerical differences of ``fun`` when omitted.
    jac_sparsity : array_like or sparse matrix, shape (m, p), optional
        Non-zero pattern of the Jacobian, for numerical differences (``jac`` omitted):
        columns that share no row are differenced together.
    retract : (x, d) -> x, optional
        How an increment ``d`` ``(p,)`` is applied (rotations as ``R Exp(d)``); ``x + d``
        otherwise.
    method : {"lm", "trf", "normal"}, optional
        Levenberg-Marquardt (MINPACK) for dense Jacobians and small sparse ones (at most
        ``DENSE_LIMIT`` entries, made dense), the trust-region method (LSMR steps) for
        larger sparse ones or a sparsity pattern; chosen from those when None. ``"normal"``:
        Levenberg-Marquardt on the normal equations ``J^T J`` (a tall Jacobian with a few
        hundred unknowns, as in a bundle adjustment: one product a step instead of a QR of
        ``J``; measured 6x faster than MINPACK on the 20-frame bundles of the tests).
    x_scale : "jac", float or ndarray
        Variable scales (``"jac"``: from the Jacobian's column norms, unit-free).
    ftol, xtol, gtol : float
        scipy's tolerances (relative cost change, relative step, scaled gradient).
    max_nfev : int, optional
        Residual evaluations per round (scipy's default when None).
    max_rounds : int
        Re-centrings under ``retract`` (see the module notes); 1 runs scipy once.
    final_jac : bool
        Under ``retract``, evaluate ``jac`` at the solution (scipy's last Jacobian is with
        respect to the increment from the last centre); ``Solution.jac`` is None otherwise.

    Returns
    -------
    Solution
    """
    x = np.asarray(x0, dtype=float).copy()
    if method == "normal":
        if jac is None:
            raise ValueError('method "normal" needs an analytic jac')
        return _normal_equations_lm(fun, jac, x, retract, max_nfev or 100, xtol)
    if method is None:
        probe = None if jac is None else jac(x)
        small = probe is not None and np.prod(probe.shape) <= DENSE_LIMIT
        if jac is not None and sparse.issparse(probe) and small:
            # a small problem: MINPACK on the dense array beats LSMR steps
            jac = _densified(jac)
            probe = None
        dense = jac_sparsity is None and (probe is None or not sparse.issparse(probe))
        method = "lm" if dense else "trf"
    if method == "lm" and jac is not None:
        done = _converged_at_start(fun, jac, x, ftol)
        if done is not None:
            return done
    options: dict[str, Any] = {
        "method": method,
        "x_scale": x_scale,
        "ftol": ftol,
        "xtol": xtol,
        "gtol": gtol,
        "max_nfev": max_nfev,
        "jac": "2-point" if jac is None else jac,
    }
    if method == "trf":
        # LSMR steps: solved to near machine precision, so that the tolerances above
        # can be met (loose inner solves stall the trust region far from them)
        options["tr_options"] = {"atol": LSMR_TOL, "btol": LSMR_TOL}
    if jac is None and jac_sparsity is not None:
        options["jac_sparsity"] = jac_sparsity
    if retract is None:
        res = _least_squares(fun, x, options)
        f = np.asarray(res.fun, dtype=float)
        return Solution(
            x=np.asarray(res.x, dtype=float),
            fun=f,
            jac=res.jac,
            cost=0.5 * float(f @ f),
            success=bool(res.success),
            nfev=int(res.nfev),
        )
    nfev = 0
    for _ in range(max(max_rounds, 1)):
        chart = _Chart(fun, jac, retract, x)
        if jac is not None:
            options["jac"] = chart.j
        res = _least_squares(chart.f, np.zeros_like(x), options)
        nfev += int(res.nfev)
        x = chart.point(np.asarray(res.x, dtype=float)).copy()
        if float(np.max(np.abs(res.x), initial=0.0)) <= RECENTRE_STEP:
            break
    # the Jacobian at the solution, as the caller defines it (scipy's is at d, not at x)
    J = res.jac if jac is None else (jac(x) if final_jac else None)
    f = np.asarray(res.fun, dtype=float)
    return Solution(
        x=x, fun=f, jac=J, cost=0.5 * float(f @ f), success=bool(res.success), nfev=nfev
    )


def _normal_equations_lm(
    fun: Callable[[FloatArray], FloatArray],
    jac: Callable[[FloatArray], Jacobian],
    x0: FloatArray,
    retract: Callable[[FloatArray, FloatArray], FloatArray] | None,
    max_iter: int,
    tol: float,
) -> Solution:
    """Levenberg-Marquardt on the normal equations (see :func:`solve`, ``method="normal"``)."""
    step_to = retract or (lambda x, d: x + d)
    x = np.asarray(x0, dtype=float).copy()
    r = np.asarray(fun(x), dtype=float)
    cost = float(r @ r)
    lam = 1e-3
    J = jac(x)
    nfev = 1
    converged = False
    for _ in range(max_iter):
        JtJ = J.T @ J
        H = np.asarray(JtJ.toarray() if sparse.issparse(JtJ) else JtJ)
        g = np.asarray(J.T @ r).ravel()
        d = np.maximum(np.diag(H), 1e-12 * max(float(np.max(np.diag(H))), 1e-300))
        while True:
            try:
                step = -np.linalg.solve(H + lam * np.diag(d), g)
            except np.linalg.LinAlgError:
                step = np.full_like(x, np.nan)
            ok = bool(np.all(np.isfinite(step)))
            x_new = step_to(x, step) if ok else x
            r_new = np.asarray(fun(x_new), dtype=float) if ok else r * np.nan
            nfev += 1
            cost_new = float(r_new @ r_new)
            if np.isfinite(cost_new) and cost_new <= cost:
                break
            lam *= 10.0
            if lam > 1e12:
                return Solution(x, r, J, 0.5 * cost, converged, nfev)
        small_step = np.linalg.norm(step) <= tol * (np.linalg.norm(x) + tol)
        # a small gain means convergence only for a near Gauss-Newton step, not a step
        # shortened by heavy damping far from the minimum
        small_gain = cost - cost_new <= tol * max(cost, 1e-300) and lam <= 1e-2
        x, r, cost = x_new, r_new, cost_new
        J = jac(x)
        lam = max(lam / 10.0, 1e-12)
        if small_step or small_gain:
            converged = True
            break
    return Solution(x, r, J, 0.5 * cost, converged, nfev)


def propagate(
    f: Callable[[FloatArray], FloatArray], x: FloatArray, cols: list[int], cov: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """``f(x)`` and its covariance, by one-sided differences over the unknowns ``cols``.

    Parameters
    ----------
    f : x -> ndarray, shape (k,)
        A quantity derived from the solution (it depends on ``x[cols]`` only).
    x : ndarray, shape (p,)
    cols : list of int
        The unknowns ``f`` depends on (a handful: differenced one by one).
    cov : ndarray, shape (len(cols), len(cols))
        Covariance of ``x[cols]``.

    Returns
    -------
    value : ndarray, shape (k,)
    covariance : ndarray, shape (k, k)
    """
    y0 = f(x)
    G = np.zeros((y0.size, len(cols)))
    for i, c in enumerate(cols):
        h = 1e-7 * max(1.0, abs(float(x[c])))
        xc = x.copy()
        xc[c] += h
        G[:, i] = (f(xc) - y0) / h
    return y0, G @ cov @ G.T


def block_jacobian(
    fun: Callable[[FloatArray], FloatArray],
    x: FloatArray,
    f0: FloatArray,
    n_shared: int,
    block_size: int,
    row_block: np.ndarray,
) -> sparse.csr_array:
    """A sparse Jacobian by differences in groups, for residuals made of independent blocks.

    The unknowns are ``n_shared`` shared ones (any row may depend on them), then one group
    of ``block_size`` unknowns per block (frame): ``x[n_shared + block_size * b + k]``
    touches only the rows of block ``b`` (``row_block``). The ``k``-th unknown of every
    block is differenced at once (as scipy's ``jac_sparsity`` grouping does), so the cost is
    ``n_shared + block_size`` evaluations of ``fun``, whatever the number of blocks.

    Parameters
    ----------
    fun : x -> ndarray, shape (m,)
    x : ndarray, shape (p,)
        ``p = n_shared + block_size * n_blocks``.
    f0 : ndarray, shape (m,)
        ``fun(x)``.
    n_shared, block_size : int
    row_block : ndarray of int, shape (m,)
        The block of each residual row.

    Returns
    -------
    scipy.sparse.csr_array, shape (m, p)
    """
    n_blocks = (x.size - n_shared) // block_size
    if n_shared + block_size * n_blocks != x.size or row_block.shape != f0.shape:
        raise ValueError(
            f"x {x.shape} is not {n_shared} shared unknowns and blocks of {block_size}, or "
            f"row_block {row_block.shape} does not match the residuals {f0.shape}"
        )
    step = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x))
    rows, cols, vals = [], [], []
    for c in range(n_shared):
        xc = x.copy()
        xc[c] += step[c]
        d = fun(xc) - f0
        nz = np.flatnonzero(d)
        rows.append(nz)
        cols.append(np.full(nz.size, c))
        vals.append(d[nz] / step[c])
    for k in range(block_size):
        idx = n_shared + k + block_size * np.arange(n_blocks)
        xc = x.copy()
        xc[idx] += step[idx]
        d = fun(xc) - f0
        nz = np.flatnonzero(d)
        col = n_shared + k + block_size * row_block[nz]
        rows.append(nz)
        cols.append(col)
        vals.append(d[nz] / step[col])
    data = np.concatenate(vals) if vals else np.zeros(0)
    rc = (
        np.concatenate(rows) if rows else np.zeros(0, int),
        np.concatenate(cols) if cols else np.zeros(0, int),
    )
    return sparse.csr_array(sparse.coo_array((data, rc), shape=(f0.size, x.size)))


def _densified(jac: Callable[[FloatArray], Jacobian]) -> Callable[[FloatArray], FloatArray]:
    """``jac`` returning a dense array (for MINPACK) instead of a sparse matrix."""
    return lambda x: np.asarray(jac(x).toarray())


def _converged_at_start(
    fun: Callable[[FloatArray], FloatArray],
    jac: Callable[[FloatArray], Jacobian],
    x: FloatArray,
    ftol: float,
) -> Solution | None:
    """The solution at ``x`` itself when the Gauss-Newton step from ``x`` predicts a
    relative decrease of the cost below ``ftol`` (MINPACK's own test, made before paying
    for a call: iterative callers start at the minimum once they have converged)."""
    f = np.asarray(fun(x), dtype=float)
    J = np.asarray(jac(x), dtype=float)
    ff = float(f @ f)
    if not (np.all(np.isfinite(J)) and np.isfinite(ff)) or J.shape[0] < J.shape[1]:
        return None
    Q = np.linalg.qr(J)[0]  # orthonormal basis of (a superset of) the range of J
    qf = Q.T @ f
    if float(qf @ qf) > ftol * ff:
        return None
    return Solution(x=x, fun=f, jac=J, cost=0.5 * ff, success=True, nfev=1)


def _least_squares(f: Callable[[FloatArray], FloatArray], d0: FloatArray, options: dict) -> Any:
    """``scipy.optimize.least_squares``; MINPACK's "tolerance too small" endings (which
    scipy cannot translate) mean the cost cannot decrease further: finish with "trf"."""
    # lazily: scipy.optimize (and scipy.spatial, which it imports) costs ~0.5 s a command,
    # and the engine's own method ("normal") needs neither
    from scipy.optimize import least_squares

    try:
        return least_squares(f, d0, **options)
    except KeyError:  # pragma: no cover - MINPACK info 6-8, seen only at machine precision
        return least_squares(f, d0, **{**options, "method": "trf"})
