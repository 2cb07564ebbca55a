"""Weighted least squares with estimated noise levels (acs_cli.core.estimation)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from acs_cli.core import estimation, se3
from acs_cli.core.joint import lever_shapes
from sample_data_gen import acs_sim as sim


def _levers(rng: np.random.Generator, n: int) -> np.ndarray:
    R = sim.random_rotations(rng, n)
    return lever_shapes(R, np.array([0.8, -1.1, 0.5]))


def _sample(rng: np.random.Generator, theta: np.ndarray, L: np.ndarray) -> np.ndarray:
    S = estimation.covariances(np.asarray(theta, float), L)
    return np.einsum("nij,nj->ni", np.linalg.cholesky(S), rng.normal(size=(L.shape[0], 3)))


def test_batched_inv3(rng: np.random.Generator) -> None:
    A = rng.normal(size=(50, 3, 3)) + 3 * np.eye(3)
    np.testing.assert_allclose(estimation.batched_inv3(A), np.linalg.inv(A), rtol=1e-9)


def test_normal_equations_and_mahalanobis(rng: np.random.Generator) -> None:
    r = rng.normal(size=(7, 3))
    J = rng.normal(size=(7, 3, 4))
    B = rng.normal(size=(7, 3, 3))
    W = B @ np.swapaxes(B, 1, 2) + np.eye(3)
    H, g = estimation.normal_equations(r, J, W)
    np.testing.assert_allclose(H, sum(J[i].T @ W[i] @ J[i] for i in range(7)), rtol=1e-10)
    np.testing.assert_allclose(g, sum(J[i].T @ W[i] @ r[i] for i in range(7)), rtol=1e-10)
    np.testing.assert_allclose(
        estimation.mahalanobis_sq(r, W), [r[i] @ W[i] @ r[i] for i in range(7)], rtol=1e-10
    )


def test_covariances(rng: np.random.Generator) -> None:
    L = _levers(rng, 4)
    S = estimation.covariances(np.array([0.3, 2.0]), L)
    np.testing.assert_allclose(S, 0.3 * np.eye(3) + 2.0 * L)


def test_outlier_threshold() -> None:
    for n in (1, 10, 30, 1000):
        t = estimation.outlier_threshold(n)
        # a clean recording of any length loses a frame with probability ~ OUTLIER_ALPHA
        assert chi2.sf(t, 3) * n == pytest.approx(estimation.OUTLIER_ALPHA)
    assert estimation.outlier_threshold(1000) > estimation.outlier_threshold(30)


def test_fit_variance_components_recovers_noise_levels(rng: np.random.Generator) -> None:
    theta = np.array([0.05**2, np.radians(1.2) ** 2])
    L = _levers(rng, 20000)
    est = estimation.fit_variance_components(_sample(rng, theta, L), L)
    np.testing.assert_allclose(est, theta, rtol=0.05)


def test_fit_variance_components_length_unit(rng: np.random.Generator) -> None:
    """Lengths in another unit (x c): theta_t scales by c^2, theta_r (rad^2) does not."""
    theta = np.array([0.05**2, np.radians(1.2) ** 2])
    L = _levers(rng, 30)
    r = _sample(rng, theta, L)
    t1 = estimation.fit_variance_components(r, L, n_params=6)
    c = 1000.0
    tc = estimation.fit_variance_components(c * r, c * c * L, n_params=6)
    np.testing.assert_allclose(tc, t1 * [c * c, 1.0], rtol=1e-6)


def test_fit_variance_components_floor_is_unit_free(rng: np.random.Generator) -> None:
    L = _levers(rng, 30)
    r = rng.normal(scale=0.05, size=(30, 3))  # translation noise only: theta_r is floored
    t1 = estimation.fit_variance_components(r, L)
    c = 1000.0  # metres -> millimetres
    tc = estimation.fit_variance_components(c * r, c * c * L)
    assert tc[0] == pytest.approx(c * c * t1[0], rel=1e-6)
    # got: theta_r = 2.5e-5 rad^2 (0.29 deg) in mm against 2.5e-11 rad^2 in m
    assert tc[1] == pytest.approx(t1[1], rel=1e-6)


def _linear_problem(
    rng: np.random.Generator, n: int
) -> tuple[estimation.LeastSquaresProblem, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``r_i = A_i x - b_i`` with constant lever shapes (the pivot problem, joint known)."""
    R = sim.random_rotations(rng, n)
    o = np.array([0.5, 1.0, -0.7])
    L = lever_shapes(R, o)
    J = np.concatenate([R, np.broadcast_to(-np.eye(3), (n, 3, 3))], axis=2)
    x_true = np.concatenate([o, [0.3, -0.2, 1.0]])
    theta = np.array([0.05**2, np.radians(1.0) ** 2])
    b = np.einsum("nij,j->ni", J, x_true) + _sample(rng, theta, L)

    def residuals(x: np.ndarray, jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        return np.einsum("nij,j->ni", J, x) - b, J

    problem = estimation.LeastSquaresProblem(residuals, lambda x: L)
    return problem, J, b, L, theta


def test_solve_with_known_noise_is_weighted_least_squares(rng: np.random.Generator) -> None:
    problem, J, b, L, theta = _linear_problem(rng, 40)
    sol = estimation.solve(problem, np.zeros(6), theta=theta, reject_outliers=False)
    W = estimation.batched_inv3(estimation.covariances(theta, L))
    H = np.einsum("nai,nab,nbj->ij", J, W, J)
    x = np.linalg.solve(H, np.einsum("nai,nab,nb->i", J, W, b))
    np.testing.assert_allclose(sol.x, x, atol=1e-9)
    np.testing.assert_allclose(sol.covariance, np.linalg.inv(H), rtol=1e-6)
    np.testing.assert_array_equal(sol.theta, theta)
    assert sol.converged and sol.inliers.all()


def test_solve_rejects_a_gross_outlier(rng: np.random.Generator) -> None:
    problem, J, b, L, theta = _linear_problem(rng, 40)
    b[7] += [2.0, -1.0, 1.5]
    sol = estimation.solve(problem, np.zeros(6), theta=theta)
    assert not sol.inliers[7] and sol.inliers.sum() == 39
    keep = np.arange(40) != 7
    W = estimation.batched_inv3(estimation.covariances(theta, L))[keep]
    H = np.einsum("nai,nab,nbj->ij", J[keep], W, J[keep])
    x = np.linalg.solve(H, np.einsum("nai,nab,nb->i", J[keep], W, b[keep]))
    np.testing.assert_allclose(sol.x, x, atol=1e-9)
    assert sol.mahalanobis_sq[7] > estimation.outlier_threshold(40)
    assert se3.check_vectors(sol.residuals).shape == (40, 3)
