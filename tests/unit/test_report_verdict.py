"""The report's verdict rules, its coverage measure and the per-corner reprojection errors."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.intrinsics import board_points
from acs_cli.core.quality import JOINT_STD, REPROJECTION, RESIDUAL
from acs_cli.report.corners import corner_residuals
from acs_cli.report.figures import coverage_fraction
from acs_cli.report.verdict import (
    THRESHOLDS,
    Check,
    StageVerdict,
    classify,
    expected_joint_residual,
    joint_checks,
    reprojection_checks,
    worst,
)

# --------------------------------------------------------------------------- thresholds


@pytest.mark.parametrize(
    ("key", "good", "borderline", "bad"),
    [
        ("reprojection_rms_px", 0.2, 2.5, 8.0),
        ("coverage", 0.8, 0.4, 0.1),
        ("joint_residual_over_noise", 1.1, 3.0, 10.0),
        ("joint_residual_over_distance", 0.002, 0.1, 0.5),
        ("joint_std_over_distance", 0.005, 0.07, 0.3),
    ],
)
def test_classify_good_borderline_bad(key: str, good: float, borderline: float, bad: float) -> None:
    assert classify(key, good) == "pass"
    assert classify(key, borderline) == "check"
    assert classify(key, bad) == "fail"
    assert classify(key, float("nan")) == "fail"
    # the limits themselves belong to the better side
    t = THRESHOLDS[key]
    assert classify(key, t.pass_limit) == "pass"
    assert t.fail_limit is not None and classify(key, t.fail_limit) == "check"


def test_warnings_ask_for_a_check_but_never_fail() -> None:
    assert classify("warnings", 0) == "pass"
    assert classify("warnings", 1) == "check"
    assert classify("warnings", 500) == "check"
    assert THRESHOLDS["warnings"].limits() == ("<= 0", "> 0", "never")


def test_thresholds_state_their_limits_in_shown_units() -> None:
    assert THRESHOLDS["coverage"].limits() == (">= 50%", ">= 25%", "< 25%")
    assert THRESHOLDS["reprojection_rms_px"].limits() == ("<= 0.5 px", "<= 5 px", "> 5 px")
    assert all(t.description and t.label for t in THRESHOLDS.values())
    # one policy: the report grades by the levels the commands warn and refuse at
    for key, rule in (
        ("reprojection_rms_px", REPROJECTION),
        ("joint_residual_over_distance", RESIDUAL),
        ("joint_std_over_distance", JOINT_STD),
    ):
        assert (THRESHOLDS[key].pass_limit, THRESHOLDS[key].fail_limit) == (rule.warn, rule.refuse)


def test_a_stage_is_its_worst_check() -> None:
    good = Check("reprojection_rms_px", 0.2, "camera A")
    half = Check("coverage", 0.3, "camera A")
    bad = Check("reprojection_rms_px", 8.0)
    assert StageVerdict("intrinsics", "x.yaml", [good]).status == "pass"
    assert StageVerdict("intrinsics", "x.yaml", [good, half]).status == "check"
    assert StageVerdict("intrinsics", "x.yaml", [half, bad, good]).status == "fail"
    assert StageVerdict("empty", "x.yaml").status == "pass"
    assert worst([]) == "pass" and worst(["check", "pass"]) == "check"
    assert half.text() == "camera A: image coverage 30% (check)"
    assert [c.key for c in reprojection_checks(0.3, None)] == ["reprojection_rms_px"]


# --------------------------------------------------------------------------- the joint


def test_expected_joint_residual_matches_simulated_pose_noise() -> None:
    """Per-axis pose noise moves a joint at distance d by the RMS the formula gives."""
    rng = np.random.default_rng(3)
    s_t, s_r_deg, o = 0.002, 0.5, np.array([0.1, -0.2, 0.6])
    n = 20000
    theta = rng.normal(0.0, np.radians(s_r_deg), (n, 3))
    moved = se3.matrix_from_rotvec(theta) @ o + rng.normal(0.0, s_t, (n, 3))
    rms = float(np.sqrt(np.mean(np.sum((moved - o) ** 2, axis=1))))
    expected = expected_joint_residual(s_t, s_r_deg, float(np.linalg.norm(o)))
    assert rms == pytest.approx(expected, rel=0.03)
    assert expected_joint_residual(s_t, s_r_deg, 0.5, cameras=2) == pytest.approx(
        np.sqrt(2.0) * expected_joint_residual(s_t, s_r_deg, 0.5)
    )


def _statuses(checks: list[Check]) -> dict[str, str]:
    return {c.key: c.status for c in checks}


def test_joint_checks_good_borderline_bad() -> None:
    d, noise = 0.4, (1e-4, 0.02)
    e = expected_joint_residual(*noise, d)
    good = joint_checks(1.1 * e, d, [1e-3, 1e-3, 2e-3], noise)
    assert _statuses(good) == {
        "joint_residual_over_noise": "pass",
        "joint_residual_over_distance": "pass",
        "joint_std_over_distance": "pass",
    }
    borderline = joint_checks(3.0 * e, d, [0.015, 0.015, 0.02], noise)
    assert set(_statuses(borderline).values()) == {"check", "pass"}
    assert _statuses(borderline)["joint_std_over_distance"] == "check"
    assert _statuses(borderline)["joint_residual_over_noise"] == "check"
    bad = joint_checks(0.12, d, [0.05, 0.05, 0.1], noise)
    assert set(_statuses(bad).values()) == {"fail"}
    # without noise, std or a distance, the checks that need them are left out
    assert [c.key for c in joint_checks(1e-4, d)] == ["joint_residual_over_distance"]
    assert joint_checks(1e-4, 0.0, [1.0, 1.0, 1.0], noise) == []


# --------------------------------------------------------------------------- coverage


def test_coverage_counts_cells_with_corners_and_skips_nan() -> None:
    w, h = 640, 480
    u, v = np.meshgrid(np.linspace(5, w / 2 - 5, 40), np.linspace(5, h / 2 - 5, 40))
    quadrant = np.column_stack([u.ravel(), v.ravel()])
    assert coverage_fraction(quadrant, (w, h)) == pytest.approx(0.25)
    with_nan = np.vstack([quadrant, [[np.nan, np.nan]] * 10])
    assert coverage_fraction(with_nan, (w, h)) == pytest.approx(0.25)
    u, v = np.meshgrid(np.linspace(5, w - 5, 60), np.linspace(5, h - 5, 60))
    assert coverage_fraction(np.column_stack([u.ravel(), v.ravel()]), (w, h)) == 1.0
    assert classify("coverage", coverage_fraction(quadrant, (w, h))) == "check"


# --------------------------------------------------------------------------- corners


def _views() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A 9x6 board seen from three poses by a distorted pinhole camera."""
    P = board_points(9, 6, 0.03)
    K = np.array([[600.0, 0.0, 322.0], [0.0, 605.0, 238.0], [0.0, 0.0, 1.0]])
    D = np.array([-0.2, 0.05, 0.001, -0.002, 0.0])
    rotvecs = [[0.1, -0.2, 0.05], [-0.3, 0.1, 0.2], [0.2, 0.35, -0.1]]
    t = [[-0.12, -0.08, 0.55], [-0.10, -0.05, 0.70], [-0.15, -0.10, 0.60]]
    T_cam_board = se3.transforms_from_rt(se3.matrix_from_rotvec(rotvecs), t)
    return P, K, D, se3.invert_transforms(T_cam_board)


def test_corner_residuals_recover_known_offsets_and_skip_unseen() -> None:
    P, K, D, T_board_cam = _views()
    T_cam_board = se3.invert_transforms(T_board_cam)
    proj = np.stack(
        [
            cv2.projectPoints(P, cv2.Rodrigues(T[:3, :3])[0], T[:3, 3], K, D)[0].reshape(-1, 2)
            for T in T_cam_board
        ]
    )
    rng = np.random.default_rng(0)
    offsets = rng.normal(0.0, 0.3, proj.shape)
    corners = proj + offsets
    corners[1, :20] = np.nan  # a partial view: corners not seen
    got = corner_residuals(corners, P, T_board_cam, "pinhole", K, D)
    seen = np.all(np.isfinite(corners), axis=2)
    assert got.residual.shape == (int(seen.sum()), 2)
    np.testing.assert_allclose(got.residual, offsets[seen], atol=1e-6)
    np.testing.assert_allclose(got.observed, corners[seen])
    assert np.bincount(got.image).tolist() == [54, 34, 54]


def test_corner_residuals_of_a_perfect_fisheye_view_are_zero() -> None:
    P, K, _, T_board_cam = _views()
    D = np.array([0.05, -0.01, 0.002, 0.0])
    T = se3.invert_transforms(T_board_cam)
    corners = np.stack(
        [
            cv2.fisheye.projectPoints(
                P.reshape(-1, 1, 3), cv2.Rodrigues(t[:3, :3])[0], t[:3, 3], K, D
            )[0].reshape(-1, 2)
            for t in T
        ]
    ).astype(float)
    got = corner_residuals(corners, P, T_board_cam, "fisheye", K, D)
    assert got.residual.shape == (3 * 54, 2)
    assert np.abs(got.residual).max() < 1e-6


def test_the_thresholds_table_of_the_docs_is_the_report_s() -> None:
    """``docs/formats.md`` lists the report's thresholds: the same limits, in order (its
    table had drifted: 1 px where the report fails above 5 px)."""
    text = (Path(__file__).resolve().parents[2] / "docs" / "formats.md").read_text()
    head = "| check | pass | check | fail |\n| --- | --- | --- | --- |\n"
    rows = text[text.index(head) + len(head) :].split("\n\n")[0].splitlines()
    cells = [tuple(c.strip() for c in r.strip("|").split("|")[-3:]) for r in rows]
    assert cells == [t.limits() for t in THRESHOLDS.values()]
