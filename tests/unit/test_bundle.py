"""Fixed-joint bundle adjustment on corner observations (acs_cli.core.bundle)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.bundle import (
    bundle_adjust_fixed_joint,
    intrinsics_vector,
    project_points,
    projection_jacobians,
    right_jacobians,
)
from acs_cli.core.joint import estimate_pivot
from sample_data_gen.acs_sim import random_unit_vectors

W, H = 1024, 768
BOARD = np.array([[c * 0.04, r * 0.04, 0.0] for r in range(6) for c in range(9)])


def _scene(rng: np.random.Generator, sigma_px: float, n: int = 20) -> dict:
    """A camera turning about a joint 0.25 m away, looking at a board 0.75 m away."""
    K = np.array([[900 * rng.uniform(0.95, 1.05), 0, 512 + rng.normal(0, 5)],
                  [0, 900 * rng.uniform(0.95, 1.05), 384 + rng.normal(0, 5)],
                  [0, 0, 1]])  # fmt: skip
    dist = np.array([rng.uniform(-0.25, 0.05), rng.uniform(-0.05, 0.1), *rng.normal(0, 1e-3, 2), 0])
    o = random_unit_vectors(rng, 1)[0] * 0.25
    R_rest = se3.matrix_from_rotvec(rng.normal(0, 0.1, 3))
    centre = BOARD.mean(axis=0)
    p_w = R_rest @ o + centre - R_rest @ np.array([0, 0, 0.75])
    Rs, obs = [], []
    while len(Rs) < n:
        angle = np.radians(rng.uniform(5, 25))
        R = se3.matrix_from_rotvec(random_unit_vectors(rng, 1)[0] * angle) @ R_rest
        x_cam = (BOARD - p_w) @ R + o
        uv = project_points(x_cam, intrinsics_vector(K, dist))
        if np.any(uv < 5) or np.any(uv[:, 0] > W - 5) or np.any(uv[:, 1] > H - 5):
            continue
        Rs.append(R)
        obs.append(uv + rng.normal(0, sigma_px, uv.shape))
    R = np.array(Rs)
    T = se3.transforms_from_rt(R, p_w - se3.rotate(R, o))
    return {"K": K, "dist": dist, "o": o, "p_w": p_w, "T": T, "obs": np.array(obs)}


def _plain_chain(s: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """OpenCV calibrateCamera + the linear pivot: the baseline the issue measures."""
    n = s["obs"].shape[0]
    _, K0, d0, rv, tv = cv2.calibrateCamera(
        [BOARD.astype(np.float32)] * n,
        [o.reshape(-1, 1, 2).astype(np.float32) for o in s["obs"]],
        (W, H), None, None,
    )  # fmt: skip
    T_cb = se3.transforms_from_rt(
        se3.matrix_from_rotvec(np.array(rv).reshape(-1, 3)), np.array(tv).reshape(-1, 3)
    )
    T_wc = se3.invert_transforms(T_cb)
    piv = estimate_pivot(T_wc, method="paper")
    return intrinsics_vector(K0, d0.ravel()), T_wc, piv.position_in_cam, piv.position_in_world


def test_projection_jacobians_match_finite_differences(rng: np.random.Generator) -> None:
    intr = np.array([900, 910, 500, 380, -0.2, 0.05, 0.001, -0.002, 0.01])
    X = rng.normal(size=(6, 3)) * 0.3 + [0, 0, 1.0]
    Di, Dp = projection_jacobians(X, intr)
    h = 1e-6
    num_i = np.stack([(project_points(X, intr + e * h) - project_points(X, intr - e * h)) / (2 * h)
                      for e in np.eye(9)], axis=-1)  # fmt: skip
    num_p = np.stack([(project_points(X + e * h, intr) - project_points(X - e * h, intr)) / (2 * h)
                      for e in np.eye(3)], axis=-1)  # fmt: skip
    np.testing.assert_allclose(Di, num_i, atol=1e-4)
    np.testing.assert_allclose(Dp, num_p, atol=1e-3)
    # the projection is OpenCV's
    K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1]])
    uv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, intr[4:])
    np.testing.assert_allclose(project_points(X, intr), uv.reshape(-1, 2), atol=1e-9)


def test_right_jacobian(rng: np.random.Generator) -> None:
    phi = rng.normal(size=(4, 3))
    Jr = right_jacobians(phi)
    for i in range(4):
        for k in range(3):
            d = np.zeros(3)
            d[k] = 1e-7
            lhs = se3.rotvec_from_matrix(
                se3.matrix_from_rotvec(phi[i]).T @ se3.matrix_from_rotvec(phi[i] + d)
            )
            np.testing.assert_allclose(lhs / 1e-7, Jr[i, :, k], atol=1e-6)


def test_exact_on_noise_free_corners(rng: np.random.Generator) -> None:
    s = _scene(rng, sigma_px=0.0)
    intr0, T0, o0, pw0 = _plain_chain(s)
    valid = np.ones(s["obs"].shape[:2], dtype=bool)
    ba = bundle_adjust_fixed_joint(s["obs"], valid, BOARD, intr0, T0, o0, pw0)
    np.testing.assert_allclose(ba.joint_in_cam, s["o"], atol=1e-7)
    np.testing.assert_allclose(ba.joint_in_world, s["p_w"], atol=1e-7)
    np.testing.assert_allclose(ba.intrinsics, intrinsics_vector(s["K"], s["dist"]), atol=1e-5)
    assert ba.rms_px < 1e-6


def test_missing_corners_are_handled(rng: np.random.Generator) -> None:
    s = _scene(rng, sigma_px=0.0)
    intr0, T0, o0, pw0 = _plain_chain(s)
    valid = rng.uniform(size=s["obs"].shape[:2]) > 0.2
    obs = np.where(valid[:, :, None], s["obs"], np.nan)  # missing corners carry no data
    ba = bundle_adjust_fixed_joint(obs, valid, BOARD, intr0, T0, o0, pw0)
    np.testing.assert_allclose(ba.joint_in_cam, s["o"], atol=1e-7)


@pytest.mark.slow
def test_beats_the_plain_chain() -> None:
    """At the renderer's corner noise (0.05 px) the joint error drops well below the plain
    OpenCV chain's and below the issue's bar of 0.6% of |O|."""
    errs = []
    for i in range(12):
        rng = np.random.default_rng([77, i])
        s = _scene(rng, sigma_px=0.05)
        intr0, T0, o0, pw0 = _plain_chain(s)
        valid = np.ones(s["obs"].shape[:2], dtype=bool)
        ba = bundle_adjust_fixed_joint(s["obs"], valid, BOARD, intr0, T0, o0, pw0)
        norm = np.linalg.norm(s["o"])
        errs.append(
            [np.linalg.norm(o0 - s["o"]) / norm, np.linalg.norm(ba.joint_in_cam - s["o"]) / norm]
        )
    e = np.mean(errs, axis=0)
    assert e[1] < 0.75 * e[0]
    assert e[1] < 0.006
