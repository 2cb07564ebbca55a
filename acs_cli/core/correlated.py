"""Covariances that cover errors correlated over time: the block (batch-means) sandwich.

Every estimator of acscal weights its frames by fitted noise levels and reports the inverse
of the information, ``C = (J^T J)^-1`` of the whitened residuals. That covariance assumes the
frames' errors are independent. Real errors are not: skin markers slide with the motion, a
robot's kinematic error follows its configuration, a tracker drifts. Then neighbouring frames
repeat one another's error, more frames are not more information, and ``C`` is too small.

The check and the cure are the same computation, run on the recording itself. The estimate
moves with the sum of the frames' *scores* ``g_i = J_i^T r_i`` (whitened residuals ``r_i``
and Jacobian rows ``J_i`` of frame ``i``): ``x - x_true ~ C sum_i g_i``. Under independent
noise the scores' sum has covariance ``C^-1``. Cut the recording into ``B`` blocks of
consecutive frames and sum the scores within each block, ``G_b``; their scatter

    Omega = B / (B - 1) sum_b (G_b - mean G) (G_b - mean G)^T

estimates the covariance of the scores' sum whatever the correlation within a block (the
batch-means, or block, estimate of a long-run covariance: Conway, *Batch means*; Newey &
West's sandwich with blocks as the kernel), so that ``C Omega C`` is the estimate's
covariance under correlated errors. It is tested per group ``g`` of unknowns reported
together (a joint's geometry, a world's pose and scale, a camera's intrinsics, a board): the
group's estimate moves by ``D_b = C[g, :] G_b`` under block ``b`` (through every unknown's
scores, by their correlation with the group), and in the group's whitened coordinates

    M = C_g^(-1/2) [B / (B - 1) sum_b (D_b - mean D) (D_b - mean D)^T] C_g^(-1/2)

is the identity under the model. Its eigenvalues ``lambda`` are the variance factors of the
block scatter against the model along its eigenvectors. Under independent noise (and blocks
of equal information), ``M`` follows a Wishart distribution ``W_d(B - 1, I) / (B - 1)``,
whose largest eigenvalue has a known tail (computed once, by a seeded simulation). When the
largest eigenvalue is beyond that tail at a false-alarm rate :data:`FALSE_ALARM`, the group's
covariance is grown along every eigenvector whose factor exceeds 1 (each factor first
corrected for block sums still correlated with their neighbours, :data:`MAX_BLOCK_RHO`),

    C_g,new = C_g + C_g^(1/2) V max(Lambda - 1, 0) V^T C_g^(1/2),

and unchanged otherwise: independent noise keeps the model's covariance (its stds stay as
calibrated as before), a recording whose blocks scatter more than the model allows gets the
scatter they show. The rest of the unknowns (a reference instant's pose, per-frame poses)
follow by regression on the grown groups, ``C_all += K Delta K^T`` with
``K = C_all[:, g] C_g^-1``.

What it cannot see: an error that is the same in every block (a constant bias; a marker that
slides the same way in every gait cycle when the blocks are shorter than a cycle but each
holds whole cycles) leaves no scatter between blocks. And blocks shorter than the errors'
correlation time understate it; :func:`block_count` keeps blocks long (at most
:data:`MAX_BLOCKS` of them) at the price of a test with ``B - 1`` degrees of freedom.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy import sparse

from acs_cli.core.correlated_tail import TAIL_TABLE
from acs_cli.core.se3 import FloatArray

#: The most blocks a recording is cut into: long blocks cover errors correlated over many
#: frames; more blocks would make the test sharper but understate such correlation.
MAX_BLOCKS = 12
#: The fewest blocks the test runs with (fewer frames than ``MIN_BLOCKS * MIN_BLOCK_FRAMES``:
#: no test, the model's covariance stands).
MIN_BLOCKS = 6
#: The fewest frames in a block.
MIN_BLOCK_FRAMES = 2
#: Per group of unknowns, the chance that independent noise alone grows its covariance (the
#: largest whitened block variance beyond the Wishart tail).
FALSE_ALARM = 0.0005
#: The largest lag-one autocorrelation of the block sums corrected for (a factor of 9 on the
#: variance): beyond, blocks this few cannot tell the correlation time.
MAX_BLOCK_RHO = 0.8
#: Draws of the seeded simulation of the Wishart tail.
_TAIL_DRAWS = 20000
#: Eigenvalues of a group's covariance below this share of its largest are a gauge or a held
#: combination: not tested, not grown.
_RANK_TOL = 1e-10


@dataclass(frozen=True)
class CorrelatedErrors:
    """What the block test found on one estimate.

    Attributes
    ----------
    blocks : int
        Blocks of consecutive frames (0: too few frames, not tested).
    frames : int
        Frames the scores came from.
    std_factor : float
        The largest factor by which a std grew (1.0: the model's covariance stands).
    grown : tuple of str
        The groups of unknowns whose covariance grew, by name.
    """

    blocks: int
    frames: int
    std_factor: float
    grown: tuple[str, ...]

    @property
    def tested(self) -> bool:
        return self.blocks > 0

    @property
    def detected(self) -> bool:
        return bool(self.grown)

    def message(self, what: str) -> str | None:
        """The one warning of every command when the covariance grew, else None."""
        if not self.detected:
            return None
        per = self.frames / max(self.blocks, 1)
        return (
            f"{what}: the residuals are correlated over time beyond independent noise "
            f"({', '.join(self.grown)}: the {self.blocks} blocks of about {per:.0f} "
            f"consecutive frames scatter more than the fitted noise allows, as skin markers, "
            f"robot kinematics or tracker drift make them); the stds are grown by up to "
            f"{self.std_factor:.1f}x to cover it"
        )


#: Not tested (no scores or too few frames).
NOT_TESTED = CorrelatedErrors(0, 0, 1.0, ())


def block_count(n: int) -> int:
    """Blocks for ``n`` frames: as many as fit :data:`MIN_BLOCK_FRAMES` frames each, at most
    :data:`MAX_BLOCKS`; 0 below :data:`MIN_BLOCKS` (not tested)."""
    b = min(MAX_BLOCKS, n // MIN_BLOCK_FRAMES)
    return b if b >= MIN_BLOCKS else 0


@lru_cache(maxsize=256)
def largest_eigenvalue_tail(dim: int, blocks: int, alpha: float = FALSE_ALARM) -> float:
    """The ``1 - alpha`` quantile of the largest eigenvalue of ``W_dim(blocks - 1, I) /
    (blocks - 1)``: the largest whitened block variance independent noise gives.

    By a seeded simulation (the same value on every run and machine), looked up in
    :data:`acs_cli.core.correlated_tail.TAIL_TABLE` where it was precomputed."""
    if alpha == FALSE_ALARM and (dim, blocks) in TAIL_TABLE:
        return TAIL_TABLE[(dim, blocks)]
    return simulated_tail(dim, blocks, alpha)


def simulated_tail(dim: int, blocks: int, alpha: float = FALSE_ALARM) -> float:
    """:func:`largest_eigenvalue_tail` by its seeded simulation, never from the table."""
    nu = blocks - 1
    rng = np.random.default_rng([20261126, dim, blocks])
    Z = rng.standard_normal((_TAIL_DRAWS, nu, dim))
    lam = np.linalg.eigvalsh(np.einsum("kni,knj->kij", Z, Z) / nu)[:, -1]
    return float(np.quantile(lam, 1.0 - alpha))


def tail_table_source(dims: int = 16) -> str:
    """The entries of :data:`acs_cli.core.correlated_tail.TAIL_TABLE`, as Python source."""
    return "\n".join(
        f"    ({d}, {b}): {simulated_tail(d, b)!r},"
        for d in range(1, dims + 1)
        for b in range(MIN_BLOCKS, MAX_BLOCKS + 1)
    )


def frame_scores(
    J: object, r: FloatArray, frame: np.ndarray, cols: Sequence[int] | np.ndarray
) -> FloatArray:
    """``(k, len(cols))``: per frame (the ``k`` distinct values of ``frame``, sorted), the sum
    of its rows' scores ``J_row^T r_row`` for the unknowns ``cols``.

    Parameters
    ----------
    J : ndarray or scipy.sparse matrix, shape (m, p)
        Whitened Jacobian rows.
    r : ndarray, shape (m,)
        Their whitened residuals.
    frame : ndarray of int, shape (m,)
        The frame of each row.
    cols : sequence of int
    """
    S = sparse.csr_matrix(J).multiply(np.asarray(r, dtype=float)[:, None]).tocsr()
    used, at = np.unique(frame, return_inverse=True)
    P = sparse.csr_matrix(
        (np.ones(frame.size), (at, np.arange(frame.size))), shape=(used.size, frame.size)
    )
    return np.asarray((P @ S)[:, np.asarray(cols, dtype=int)].toarray())


def block_sums(scores: FloatArray, blocks: int) -> FloatArray:
    """``(blocks, q)``: the scores ``(n, q)`` summed over ``blocks`` runs of consecutive
    frames of near-equal length."""
    edges = np.linspace(0, scores.shape[0], blocks + 1).round().astype(int)
    return np.add.reduceat(scores, edges[:-1], axis=0)


def _roots(C: FloatArray) -> tuple[FloatArray, FloatArray, int]:
    """``C^(1/2)`` and ``C^(-1/2)`` of a symmetric PSD matrix (directions below
    :data:`_RANK_TOL` of the largest eigenvalue zeroed in both) and the rank kept."""
    w, U = np.linalg.eigh(0.5 * (C + C.T))
    top = float(w[-1]) if w.size else 0.0
    keep = w > _RANK_TOL * max(top, 0.0)
    root = np.where(keep, np.sqrt(np.maximum(w, 0.0)), 0.0)
    inv = np.where(keep, 1.0 / np.where(keep, root, 1.0), 0.0)
    return np.asarray((U * root) @ U.T), np.asarray((U * inv) @ U.T), int(keep.sum())


def excess_covariance(C: FloatArray, D: FloatArray) -> tuple[FloatArray, float, bool]:
    """The growth ``Delta`` of one group's covariance ``C`` ``(d, d)`` from the blocks'
    deflections of its estimate ``D`` ``(B, d)`` (``D_b = C[g, :] G_b``: what block ``b``'s
    scores move the group by): zero unless the largest whitened block variance is beyond
    the Wishart tail at the false-alarm rate :data:`FALSE_ALARM`.

    Returns
    -------
    Delta : ndarray, shape (d, d)
    std_factor : float
        The largest std factor ``sqrt(max lambda)`` along an eigenvector (1.0 when not grown).
    grown : bool
    """
    B, d = D.shape
    S, Si, rank = _roots(C)
    if rank == 0 or B < 2:
        return np.zeros((d, d)), 1.0, False
    Z = (D - D.mean(axis=0)) @ Si  # whitened, centred (the scores sum to ~0)
    M = B / (B - 1) * (Z.T @ Z)
    lam, V = np.linalg.eigh(0.5 * (M + M.T))
    if not lam[-1] > largest_eigenvalue_tail(rank, B):
        return np.zeros((d, d)), 1.0, False
    # blocks shorter than the errors' correlation time leave the block sums themselves
    # correlated: along each direction, their lag-one autocorrelation rho (AR(1), clipped
    # to [0, MAX_BLOCK_RHO]) scales the variance by (1 + rho) / (1 - rho) (prewhitening,
    # as Andrews & Monahan's HAC estimator does)
    Y = Z @ V  # (B, d): the block sums along the eigenvectors
    rho = np.sum(Y[1:] * Y[:-1], axis=0) / np.maximum(np.sum(Y**2, axis=0), 1e-300)
    rho = np.clip(rho, 0.0, MAX_BLOCK_RHO)
    lam = lam * (1.0 + rho) / (1.0 - rho)
    grow = np.maximum(lam - 1.0, 0.0)
    Delta = S @ (V * grow) @ V.T @ S
    return np.asarray(0.5 * (Delta + Delta.T)), float(np.sqrt(1.0 + grow.max())), True


def covariance_with_correlated_errors(
    cov: FloatArray,
    scores: FloatArray,
    cols: Sequence[int] | np.ndarray | None = None,
    groups: Mapping[str, Sequence[int]] | None = None,
) -> tuple[FloatArray, CorrelatedErrors]:
    """The model covariance ``cov``, grown where the recording's blocks of consecutive
    frames show errors correlated over time (see the module notes).

    Parameters
    ----------
    cov : ndarray, shape (p, p)
        The model's covariance: the inverse information of the whitened residuals.
    scores : ndarray, shape (n, q)
        Per frame, in time order, the scores ``J_i^T r_i`` of its whitened residuals for the
        unknowns ``cols`` (frames left out of the fit, such as rejected outliers, omitted).
    cols : sequence of int, optional
        The ``q`` columns of ``cov`` the scores are of (all when None); the others follow
        them by regression.
    groups : dict of str to sequence of int, optional
        Named groups of positions in ``cols`` tested together (the unknowns one quantity is
        reported from); one group "estimate" of all of them when None.

    Returns
    -------
    covariance : ndarray, shape (p, p)
    found : CorrelatedErrors
    """
    cov = np.asarray(cov, dtype=float)
    scores = np.asarray(scores, dtype=float)
    p = cov.shape[0]
    idx = np.arange(p) if cols is None else np.asarray(list(cols), dtype=int)
    n = scores.shape[0]
    B = block_count(n)
    if B == 0 or idx.size == 0 or not np.all(np.isfinite(scores)):
        return cov, CorrelatedErrors(0, n, 1.0, ())
    groups = {"estimate": range(idx.size)} if groups is None else groups
    G = block_sums(scores, B)
    Cq = cov[np.ix_(idx, idx)]
    Delta = np.zeros_like(Cq)
    factor = 1.0
    grown: list[str] = []
    for name, members in groups.items():
        g = np.asarray(list(members), dtype=int)
        if g.size == 0:
            continue
        # the group's estimate moves by C[g, :] G_b under block b's scores (the other
        # unknowns' scores move it too, through their correlation with it)
        D, f, hit = excess_covariance(Cq[np.ix_(g, g)], G @ Cq[:, g])
        if hit:
            Delta[np.ix_(g, g)] += D
            factor = max(factor, f)
            grown.append(name)
    found = CorrelatedErrors(B, n, factor, tuple(grown))
    if not grown:
        return cov, found
    # every unknown follows the grown ones by regression: K = C[:, q] C_q^+
    K = cov[:, idx] @ np.linalg.pinv(Cq, rcond=_RANK_TOL, hermitian=True)
    out = cov + K @ Delta @ K.T
    return np.asarray(0.5 * (out + out.T)), found
