"""The block sandwich (acs_cli.core.correlated): independent noise keeps the model's
covariance; errors correlated over time get stds that cover them."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core import correlated as cc
from acs_cli.core.correlated import largest_eigenvalue_tail, simulated_tail
from acs_cli.core.correlated_tail import TAIL_TABLE


def _line_fit(rng: np.random.Generator, n: int, rho: float) -> tuple[np.ndarray, np.ndarray]:
    """A straight line and an offset fitted to ``n`` samples whose errors are AR(1) with
    lag-one correlation ``rho`` (unit variance); the estimate's error and its covariance."""
    t = np.linspace(-1.0, 1.0, n)
    X = np.stack([np.ones(n), t, np.sin(3 * t)], axis=1)
    e = np.empty(n)
    e[0] = rng.standard_normal()
    innov = rng.standard_normal(n) * np.sqrt(1 - rho**2)
    for i in range(1, n):
        e[i] = rho * e[i - 1] + innov[i]
    beta, *_ = np.linalg.lstsq(X, e, rcond=None)  # the truth is zero
    r = e - X @ beta
    s2 = float(r @ r) / (n - 3)  # the fitted noise level, as every estimator fits it
    Xw, rw = X / np.sqrt(s2), r / np.sqrt(s2)
    cov = np.linalg.inv(Xw.T @ Xw)
    grown, found = cc.covariance_with_correlated_errors(cov, Xw * rw[:, None])
    return beta, np.stack([cov, grown]), found  # type: ignore[return-value]


def _z2(beta: np.ndarray, C: np.ndarray) -> float:
    return float(beta @ np.linalg.solve(C, beta)) / beta.size


def test_independent_noise_keeps_the_models_covariance(rng: np.random.Generator) -> None:
    grown = 0
    for _ in range(300):
        _, (C, G), found = _line_fit(rng, 240, 0.0)
        assert found.tested and found.blocks == cc.MAX_BLOCKS
        grown += found.detected
        if not found.detected:
            np.testing.assert_array_equal(C, G)
    # 0.05% a group for blocks of equal information; these blocks differ (a line fit's ends
    # weigh more), which fattens the tail a little
    assert grown <= 6


def test_errors_correlated_over_time_get_stds_that_cover_them(rng: np.random.Generator) -> None:
    model, block, seen = [], [], 0
    for _ in range(150):
        beta, (C, G), found = _line_fit(rng, 600, 0.9)
        seen += found.detected
        assert not found.detected or found.std_factor > 1.5
        model.append(_z2(beta, C))
        block.append(_z2(beta, G))
    assert seen >= 0.95 * 150
    assert np.sqrt(np.mean(model)) > 2.5  # the model's stds claim far too much
    # 11 degrees of freedom and blocks about 2.5 correlation times long: the stds cover most
    # of the correlation (measured 1.70 against the model's 4.4 on these seeds)
    assert 0.6 < np.sqrt(np.mean(block)) < 0.5 * np.sqrt(np.mean(model))


def test_other_unknowns_follow_the_grown_ones_by_regression(rng: np.random.Generator) -> None:
    A = rng.standard_normal((4, 4))
    cov = A @ A.T + np.eye(4)
    scores = np.cumsum(rng.standard_normal((120, 2)), axis=0)  # strongly correlated in time
    out, found = cc.covariance_with_correlated_errors(cov, scores, cols=[0, 1])
    assert found.detected and found.grown == ("estimate",)
    K = cov[:, :2] @ np.linalg.inv(cov[:2, :2])
    Delta = out[:2, :2] - cov[:2, :2]
    np.testing.assert_allclose(out, cov + K @ Delta @ K.T, atol=1e-12)
    w = np.linalg.eigvalsh(out - cov)
    assert np.all(w > -1e-12 * w.max())  # never shrinks


def test_too_few_frames_are_not_tested() -> None:
    out, found = cc.covariance_with_correlated_errors(np.eye(2), np.ones((5, 2)))
    assert not found.tested and not found.detected and found.std_factor == 1.0
    np.testing.assert_array_equal(out, np.eye(2))
    assert found.message("the joint") is None


@pytest.mark.parametrize(("dim", "blocks"), [(1, 6), (3, 12), (6, 12)])
def test_the_wishart_tail_is_reproducible_and_above_one(dim: int, blocks: int) -> None:
    a = cc.largest_eigenvalue_tail(dim, blocks)
    cc.largest_eigenvalue_tail.cache_clear()
    assert cc.largest_eigenvalue_tail(dim, blocks) == a
    assert a > 1.5


def test_the_message_names_what_grew() -> None:
    found = cc.CorrelatedErrors(12, 600, 3.2, ("joint knee",))
    msg = found.message("the rig")
    assert msg is not None and "joint knee" in msg and "3.2x" in msg and "12 blocks" in msg


@pytest.mark.parametrize(("dim", "blocks"), [(1, 6), (3, 12), (6, 9)])
def test_the_precomputed_tail_is_the_simulation_bit_for_bit(dim: int, blocks: int) -> None:
    """The table only saves time: the seeded simulation gives the same number."""
    assert TAIL_TABLE[(dim, blocks)] == simulated_tail(dim, blocks)
    assert largest_eigenvalue_tail(dim, blocks) == TAIL_TABLE[(dim, blocks)]
    # outside the table (another rate, a larger group) it is simulated
    assert largest_eigenvalue_tail(dim, blocks, 0.01) == simulated_tail(dim, blocks, 0.01)
    assert (17, 6) not in TAIL_TABLE and largest_eigenvalue_tail(17, 6) > 1.0
