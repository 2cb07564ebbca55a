"""Weighted least squares with estimated noise levels (acs_cli.core.estimation)."""

from __future__ import annotations

from math import comb

import numpy as np
import pytest
from scipy.stats import chi2, f

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
    alpha, heavy = estimation.OUTLIER_ALPHA, estimation.OUTLIER_ALPHA_HEAVY
    for n in (1, 10, 30, 1000):
        for dof in (3.0, 20.0, 300.0):
            t = estimation.outlier_threshold(n, dof)
            # each noise model's per-recording false-rejection rate is within its budget,
            # and the threshold is that of one of them
            assert f.sf(t, 3, dof) * n <= alpha * (1 + 1e-9)
            assert f.sf(t, 1, dof) * n <= heavy * (1 + 1e-9)
            assert max(f.sf(t, 3, dof) * n / alpha, f.sf(t, 1, dof) * n / heavy) == (
                pytest.approx(1.0)
            )
        # known noise levels: the statistic is chi2(m) / m
        t = estimation.outlier_threshold(n, np.inf)
        assert max(chi2.sf(3 * t, 3) * n / alpha, chi2.sf(t, 1) * n / heavy) == pytest.approx(1.0)
    assert estimation.outlier_threshold(1000, 80.0) > estimation.outlier_threshold(30, 80.0)
    # a noise level estimated from fewer residuals: a larger threshold
    assert estimation.outlier_threshold(30, 5.0) > estimation.outlier_threshold(30, 80.0)
    assert estimation.outlier_threshold(30, 0.0) == np.inf
    # a share of the budgets; the masking test: g frames jointly, F(g m, dof) and
    # F(g d, dof), the budgets shared among the C(n, g) groups
    for n, g, dof, share in ((30, 1, 80.0, 0.75), (15, 2, 35.0, 0.25), (30, 3, 71.0, 0.25)):
        t = estimation.outlier_threshold(n, dof, group=g, share=share)
        tests = comb(n, g) / share
        assert max(f.sf(t, 3 * g, dof) * tests / alpha, f.sf(t, g, dof) * tests / heavy) == (
            pytest.approx(1.0)
        )
    # a trimmed noise level is too small: the threshold grows by the consistency factor
    # (got: 1.26 for 10% trimmed, the Gaussian model's F_5(q) / 0.9 = 0.80)
    assert estimation.outlier_threshold(30, 80.0, trimmed=0.1) > 1.2 * (
        estimation.outlier_threshold(30, 80.0)
    )


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
    assert sol.mahalanobis_sq[7] > 3 * estimation.outlier_threshold(40, np.inf)
    assert se3.check_vectors(sol.residuals).shape == (40, 3)


def _pivot_problem(
    rng: np.random.Generator, n: int, outliers: int = 0
) -> tuple[estimation.LeastSquaresProblem, np.ndarray, np.ndarray]:
    """:func:`_linear_problem` with its first ``outliers`` frames moved by 1 m (20 times the
    translation noise), their indices, and a start."""
    problem, J, b, _, _ = _linear_problem(rng, n)
    bad = np.arange(outliers)
    b[bad] += sim.random_unit_vectors(rng, outliers)
    x0, *_ = np.linalg.lstsq(J.reshape(-1, 6), b.reshape(-1), rcond=None)
    return problem, bad, x0


def test_studentized_residuals_are_leave_one_out_predictions(rng: np.random.Generator) -> None:
    """``T_i = e_i^T (I - H_ii)^{-1} e_i`` is frame i's squared prediction error by the
    fit without it, in units of its covariance ``Sigma_i + J_i Cov_(i) J_i^T``."""
    problem, J, b, L, theta = _linear_problem(rng, 12)
    sol = estimation.solve(problem, np.zeros(6), theta=theta, reject_outliers=False)
    W = estimation.batched_inv3(estimation.covariances(theta, L))
    fit = estimation._Fit(sol.x, theta, W, True, 1)
    st = estimation._studentize(problem, fit, np.ones(12, dtype=bool), known_scale=True)
    for i in (0, 5, 11):
        keep = np.arange(12) != i
        H = np.einsum("nai,nab,nbj->ij", J[keep], W[keep], J[keep])
        x = np.linalg.solve(H, np.einsum("nai,nab,nb->i", J[keep], W[keep], b[keep]))
        d = J[i] @ x - b[i]
        C = np.linalg.inv(W[i]) + J[i] @ np.linalg.inv(H) @ J[i].T
        assert 3 * st.stat[i] == pytest.approx(d @ np.linalg.solve(C, d), rel=1e-6)


def test_group_statistic_is_a_joint_prediction(rng: np.random.Generator) -> None:
    """The masking test's statistic of frames ``G`` left out: their stacked prediction
    errors by the fit without them, in units of their joint covariance (cross terms
    included), over ``g m`` and the noise level of the fit (``S / nu``)."""
    problem, J, b, L, theta = _linear_problem(rng, 12)
    group = np.array([2, 7])
    mask = np.ones(12, dtype=bool)
    mask[group] = False
    W = estimation.batched_inv3(estimation.covariances(theta, L))
    H = np.einsum("nai,nab,nbj->ij", J[mask], W[mask], J[mask])
    x = np.linalg.solve(H, np.einsum("nai,nab,nb->i", J[mask], W[mask], b[mask]))
    fit = estimation._Fit(x, theta, W, True, 1)
    stat, nu, dim = estimation._group_statistic(problem, fit, mask, group)
    d = (np.einsum("nij,j->ni", J[group], x) - b[group]).reshape(-1)
    Jg = J[group].reshape(-1, 6)
    C = np.zeros((6, 6))
    C[:3, :3], C[3:, 3:] = np.linalg.inv(W[2]), np.linalg.inv(W[7])
    C += Jg @ np.linalg.inv(H) @ Jg.T
    r = np.einsum("nij,j->ni", J[mask], x) - b[mask]
    S = float(np.sum(estimation.mahalanobis_sq(r, W[mask])))
    assert (dim, nu) == (3, pytest.approx(3 * 10 - 6 - 1))
    assert stat == pytest.approx((d @ np.linalg.solve(C, d)) / 6 / (S / nu), rel=1e-6)


def test_small_clean_recordings_keep_every_frame(rng: np.random.Generator) -> None:
    """The chi-square(3) test of raw distances rejected a clean frame in 74%, 52% and 20% of
    4-, 5- and 6-frame recordings; the studentised test in at most ~1.5%
    (benchmarks/bench_outliers.py): at most 3 of these 60 may lose a frame (expected
    0-1; P(4 or more) < 0.5% at a 1.5% rate)."""
    lost = 0
    for n in (4, 5, 6):
        for _ in range(20):
            problem, _, x0 = _pivot_problem(rng, n)
            lost += int(not estimation.solve(problem, x0).inliers.all())
    assert lost <= 3


def test_gross_outliers_are_rejected(rng: np.random.Generator) -> None:
    for _ in range(5):
        problem, bad, x0 = _pivot_problem(rng, 30, 3)
        sol = estimation.solve(problem, x0)
        expected = np.ones(30, dtype=bool)
        expected[bad] = False
        np.testing.assert_array_equal(sol.inliers, expected)


def test_gross_outlier_in_a_small_recording(rng: np.random.Generator) -> None:
    """6 frames, one moved by 20 sigma. It is caught unless the fitted rotation noise
    absorbs it (measured: 35 of 40 caught, no clean frame lost); at least 7 of these 10."""
    caught = 0
    for _ in range(10):
        problem, _, x0 = _pivot_problem(rng, 6, 1)
        inliers = estimation.solve(problem, x0).inliers
        assert inliers[1:].all()
        caught += int(not inliers[0])
    assert caught >= 7


def test_pluslib_stylus_outliers_are_rejected(rng: np.random.Generator) -> None:
    """PlusLib's stylus test (vtkStylusCalibrationTest.cxx): 100 poses of a stylus turning
    about its 210 mm tip, 5 replaced by random poses (rotations about x, y, z uniform in
    +-160 degrees, translations uniform in +-1000 mm); tracker noise 0.1 deg / 0.25 mm."""
    from acs_cli.core.joint import estimate_pivot

    T, bad, tip = sim.pluslib_stylus_recording(rng)
    est = estimate_pivot(T, "refined")
    expected = np.ones(100, dtype=bool)
    expected[bad] = False
    np.testing.assert_array_equal(est.inliers, expected)
    assert np.linalg.norm(est.position_in_cam - tip) < 0.5  # PlusLib's tolerance (mm)


def test_tail_shape(rng: np.random.Generator) -> None:
    """Gaussian 3-vectors: about 3 degrees of freedom (less the margin); a Gaussian
    magnitude along a random direction (IGSIO's noise): 1; too few frames: 1."""
    margin = estimation.TAIL_SHAPE_MARGIN
    gauss = np.sum(rng.normal(size=(4000, 3)) ** 2, axis=1)
    assert estimation.tail_shape(gauss, 3) == pytest.approx(3.0 - margin, abs=0.15)
    one_direction = 3.0 * rng.normal(size=4000) ** 2
    assert estimation.tail_shape(one_direction, 3) == 1.0
    assert estimation.tail_shape(gauss[: estimation.TAIL_SHAPE_MIN_FRAMES - 1], 3) == 1.0
    # a heavier reference, a larger threshold
    assert estimation.outlier_threshold(100, 200.0, shape=1.0) > estimation.outlier_threshold(
        100, 200.0, shape=2.5
    )


def test_down_weights_taper_from_the_gaussian_level_to_the_threshold() -> None:
    stat = np.array([0.0, 4.0, 5.0, 6.0, 7.5, 9.0, 10.0, 50.0])
    w = estimation.down_weights(stat, 5.0, 10.0)
    assert np.all(w[:3] == 1.0) and np.all(w[-2:] <= 1e-6)
    assert np.all(np.diff(w) <= 0.0) and 0.0 < w[4] < 1.0
    assert w[4] == pytest.approx((1 - 0.5**2) ** 2)
    np.testing.assert_array_equal(estimation.down_weights(stat, 5.0, 5.0), np.ones(8))


def _linear_without_first(
    J: np.ndarray, b: np.ndarray, L: np.ndarray
) -> estimation.LeastSquaresProblem:
    """The problem of :func:`_linear_problem` without its first frame."""
    J, b, L = J[1:], b[1:], L[1:]

    def residuals(x: np.ndarray, jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        return np.einsum("nij,j->ni", J, x) - b, J

    return estimation.LeastSquaresProblem(residuals, lambda x: L)


def test_a_doubtful_frame_below_the_threshold_is_down_weighted_not_dropped(
    rng: np.random.Generator,
) -> None:
    """12 frames, one moved by 5-12 sigma: where the (heavy-tailed) rejection threshold
    keeps it and the Gaussian level doubts it, its weight is below 1, no frame is dropped,
    and the estimate is nearer the fit without it than the unweighted fit of all frames."""
    seen = 0
    for shift in np.linspace(0.25, 0.6, 8):  # 5-12 times the 0.05 m translation noise
        problem, J, b, L, _ = _linear_problem(rng, 12)
        b[0] += shift * sim.random_unit_vectors(rng, 1)[0]
        sol = estimation.solve(problem, np.zeros(6))
        assert sol.weights.shape == (12,) and np.all(sol.weights[1:] == 1.0)
        if not sol.inliers.all() or sol.weights[0] == 1.0:
            continue  # dropped, or (a shift along the noise) not doubted
        seen += 1
        plain = estimation.solve(problem, np.zeros(6), reject_outliers=False)
        without = estimation.solve(
            _linear_without_first(J, b, L), np.zeros(6), reject_outliers=False
        )
        assert np.linalg.norm(sol.x - without.x) < np.linalg.norm(plain.x - without.x)
        # its distance is against the noise levels alone, not shrunk by its weight
        W = estimation.batched_inv3(estimation.covariances(sol.theta, L))
        np.testing.assert_allclose(
            sol.mahalanobis_sq, estimation.mahalanobis_sq(sol.residuals, W), rtol=1e-9
        )
    assert seen >= 2
