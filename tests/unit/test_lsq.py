"""The least-squares engine (acs_cli.core.lsq) and the analytic Jacobians that replaced
finite-difference loops, each checked against central differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from acs_cli.core import lsq, paper, relpose, se3
from sample_data_gen import acs_sim as sim


def _rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    return sim.random_rotations(rng, n)


def _pose(rng: np.random.Generator) -> np.ndarray:
    return se3.transforms_from_rt(_rotations(rng, 1)[0], rng.normal(size=3))


# ----------------------------------------------------------------------------- the engine


def _kabsch(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The closed form: ``R, t`` minimising ``sum |Q_i - (R P_i + t)|^2``."""
    mp, mq = P.mean(axis=0), Q.mean(axis=0)
    U, _, Vt = np.linalg.svd((Q - mq).T @ (P - mp))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return R, mq - R @ mp


def _rotation_problem(rng: np.random.Generator, n: int = 40):
    """Fit a rotation and a translation to point pairs: ``r_i = R p_i + t - q_i``."""
    P = rng.normal(size=(n, 3))
    R_true = _rotations(rng, 1)[0]
    t_true = rng.normal(size=3)
    Q = P @ R_true.T + t_true + 1e-3 * rng.normal(size=(n, 3))

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return se3.matrix_from_rotvec(x[:3]), x[3:]

    def fun(x: np.ndarray) -> np.ndarray:
        R, t = unpack(x)
        return (P @ R.T + t - Q).ravel()

    def jac(x: np.ndarray) -> np.ndarray:
        R, _ = unpack(x)
        J = np.zeros((n, 3, 6))
        J[:, :, :3] = -np.matmul(R, se3.skew(P))  # R Exp(e) p = R p - R [p]x e
        J[:, :, 3:] = np.eye(3)
        return J.reshape(-1, 6)

    def retract(x: np.ndarray, d: np.ndarray) -> np.ndarray:
        out = x + d
        out[:3] = se3.rotvec_from_matrix(unpack(x)[0] @ se3.matrix_from_rotvec(d[:3]))
        return out

    R0, t0 = _kabsch(P, Q)
    return fun, jac, retract, P, Q, R0, t0


def test_engine_on_the_manifold_finds_the_closed_form(rng: np.random.Generator) -> None:
    fun, jac, retract, _, _, R0, t0 = _rotation_problem(rng)
    x0 = np.zeros(6)  # far from the answer: several re-centrings
    sol = lsq.solve(fun, x0, jac=jac, retract=retract)
    assert sol.success
    np.testing.assert_allclose(se3.matrix_from_rotvec(sol.x[:3]), R0, atol=1e-9)
    np.testing.assert_allclose(sol.x[3:], t0, atol=1e-9)
    np.testing.assert_allclose(sol.jac, jac(sol.x))
    np.testing.assert_allclose(sol.fun, fun(sol.x))
    assert sol.cost == pytest.approx(0.5 * float(fun(sol.x) @ fun(sol.x)))


def test_engine_with_numerical_and_sparse_jacobians(rng: np.random.Generator) -> None:
    fun, jac, retract, *_ = _rotation_problem(rng)
    x_ref = lsq.solve(fun, np.zeros(6), jac=jac, retract=retract).x
    # finite differences through the chart
    sol = lsq.solve(fun, np.zeros(6), retract=retract)
    np.testing.assert_allclose(sol.x, x_ref, atol=1e-7)
    # a sparse analytic Jacobian: the trust-region method with LSMR steps
    sparse_jac = lambda x: sparse.csr_array(jac(x))  # noqa: E731
    sol = lsq.solve(fun, x_ref + 1e-3, jac=sparse_jac, retract=retract, method="trf")
    np.testing.assert_allclose(sol.x, x_ref, atol=1e-7)
    assert sparse.issparse(sol.jac)
    # small sparse problems are solved densely (MINPACK)
    sol = lsq.solve(fun, x_ref + 1e-3, jac=sparse_jac, retract=retract)
    np.testing.assert_allclose(sol.x, x_ref, atol=1e-7)
    assert isinstance(sol.jac, np.ndarray)
    # numerical differences grouped by a sparsity pattern (all columns share rows here)
    lin = rng.normal(size=(30, 4))
    b = rng.normal(size=30)
    sol = lsq.solve(lambda x: lin @ x - b, np.zeros(4), jac_sparsity=np.ones((30, 4)))
    np.testing.assert_allclose(sol.x, np.linalg.lstsq(lin, b, rcond=None)[0], atol=1e-7)


def test_engine_returns_at_once_at_the_minimum(rng: np.random.Generator) -> None:
    A = rng.normal(size=(20, 3))
    b = rng.normal(size=20)
    x = np.linalg.lstsq(A, b, rcond=None)[0]
    sol = lsq.solve(lambda x: A @ x - b, x, jac=lambda x: A)
    assert sol.nfev == 1 and sol.success
    np.testing.assert_array_equal(sol.x, x)


# ----------------------------------------------------------------------------- Jacobians


def _central(f, x: np.ndarray, eps: float = 1e-6) -> np.ndarray:
    """Central differences of ``f`` ``(k,)`` at ``x`` ``(p,)``: ``(k, p)`` (test only)."""
    cols = []
    for k in range(x.size):
        e = np.zeros_like(x)
        e[k] = eps
        cols.append((f(x + e) - f(x - e)) / (2 * eps))
    return np.stack(cols, axis=1)


def _log_diff(R0: np.ndarray, R1: np.ndarray) -> np.ndarray:
    return se3.rotvec_from_matrix(R0.T @ R1)


def test_rpy_right_jacobian(rng: np.random.Generator) -> None:
    for _ in range(5):
        rpy = rng.uniform(-1.4, 1.4, size=3)
        R = se3.matrix_from_rpy_deg(np.degrees(rpy))
        num = _central(lambda p, R=R: _log_diff(R, se3.matrix_from_rpy_deg(np.degrees(p))), rpy)
        np.testing.assert_allclose(se3.rpy_right_jacobian(rpy), num, atol=1e-8)


def _pose_diff(T0: np.ndarray, T1: np.ndarray) -> np.ndarray:
    return np.concatenate([_log_diff(T0[:3, :3], T1[:3, :3]), T1[:3, 3] - T0[:3, 3]])


def test_inverse_pose_covariance_matches_finite_differences(rng: np.random.Generator) -> None:
    """The two-body rig reports ``T_a_b``; the pair's ``T_b_a`` is its inverse, with the
    covariance carried over (both as right rotation perturbation, translation)."""
    T = _pose(rng)
    T0 = se3.invert_transforms(T)

    def inverse(d: np.ndarray) -> np.ndarray:
        Td = se3.transforms_from_rt(T[:3, :3] @ se3.matrix_from_rotvec(d[:3]), T[:3, 3] + d[3:])
        return _pose_diff(T0, se3.invert_transforms(Td))

    G = _central(inverse, np.zeros(6))
    C = rng.normal(size=(6, 6)) * 1e-3
    C = C @ C.T
    np.testing.assert_allclose(relpose._inverse_covariance(T, C), G @ C @ G.T, atol=1e-10)


def test_paper_pose_std_matches_finite_differences(rng: np.random.Generator) -> None:
    T = _pose(rng)

    def quantities(d: np.ndarray) -> np.ndarray:
        R = T[:3, :3] @ se3.matrix_from_rotvec(d[:3])
        t = T[:3, 3] + d[3:]
        return np.concatenate([se3.rpy_deg_from_matrix(R.T), -R.T @ t])

    G = _central(quantities, np.zeros(6))
    C = rng.normal(size=(6, 6)) * 1e-3
    C = C @ C.T
    std = np.sqrt(np.diag(G @ C @ G.T))
    rpy_std, t_std = relpose.paper_pose_std(T, C)
    np.testing.assert_allclose(np.concatenate([rpy_std, t_std]), std, rtol=1e-6)


def test_paper_refinement_jacobian(rng: np.random.Generator, monkeypatch) -> None:
    """The paper's eq. (25)/(44) refinement (roll, pitch, yaw, T, O, phi) has an analytic
    Jacobian: compare it with differences of its residuals."""
    seen: list = []
    solve = lsq.solve

    def spy(fun, x0, **kw):
        seen.append((fun, kw["jac"], np.asarray(x0, float)))
        return solve(fun, x0, **kw)

    monkeypatch.setattr(lsq, "solve", spy)
    n = 12
    Ta = se3.transforms_from_rt(_rotations(rng, n), rng.normal(size=(n, 3)))
    Tb = se3.transforms_from_rt(_rotations(rng, n), rng.normal(size=(n, 3)))
    for unknown_scale in (False, True):
        seen.clear()
        paper.relative_pose_paper(Ta, Tb, rng.normal(size=3), 0, unknown_scale)
        fun, jac, x0 = seen[0]
        x = x0 + 0.1 * rng.normal(size=x0.size)
        np.testing.assert_allclose(jac(x), _central(fun, x), atol=1e-6)
