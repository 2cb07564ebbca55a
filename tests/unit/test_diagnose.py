"""What the poses do not fit (issue 13 item 2): :mod:`acs_cli.core.diagnose`."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.diagnose import (
    MUCH_BETTER,
    SUSPICIOUS_FRACTION,
    TimedPair,
    diagnose_fixed_joint,
    diagnose_overlap,
    diagnose_relpose,
    expected_residual_rms,
    fit_is_suspicious,
    pair_length_scale,
    paper_method_misfit,
    reordered_quaternions,
    scaled_prior,
)
from acs_cli.core.joint import estimate_joint_fixed, estimate_pivot
from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.quality import length_scale
from acs_cli.core.relpose import JointPrior, estimate_relpose
from sample_data_gen.acs_sim import (
    SyntheticRig,
    add_pose_noise,
    fixed_joint_sequence,
    general_sequence,
    make_rig,
    scale_translations,
    smooth_general_sequence,
)

SIGMA_ROT_DEG, SIGMA_TRANS = 0.5, 0.003


def _noisy(rng: np.random.Generator, T: np.ndarray) -> np.ndarray:
    return add_pose_noise(rng, T, SIGMA_ROT_DEG, SIGMA_TRANS)


@pytest.fixture(scope="module")
def fixed() -> tuple[np.ndarray, np.ndarray]:
    """A fixed-joint session of a rig whose joint is 0.1-0.5 m from each camera (A, B)."""
    rng = np.random.default_rng(13)
    seq = fixed_joint_sequence(rng, make_rig(rng, (0.1, 0.5)), 50)
    return _noisy(rng, seq.T_wa_a), _noisy(rng, seq.T_wb_b)


@pytest.fixture(scope="module")
def general() -> tuple[np.ndarray, np.ndarray, JointPrior, JointPrior, SyntheticRig]:
    """General motion of one rig (poses of A and B), the joint file of a fixed-joint session
    of that rig, that of another rig, and the rig."""
    rng = np.random.default_rng(7)
    rig, other = make_rig(rng, (0.1, 0.5)), make_rig(rng, (0.1, 0.5))
    priors = []
    for r in (rig, other):
        s = fixed_joint_sequence(rng, r, 50)
        j = estimate_joint_fixed(_noisy(rng, s.T_wa_a), _noisy(rng, s.T_wb_b))
        priors.append(JointPrior(j.position_in_a, j.position_in_b, j.covariance_a, j.covariance_b))
    seq = general_sequence(rng, rig, 40)
    return _noisy(rng, seq.T_wa_a), _noisy(rng, seq.T_wb_b), priors[0], priors[1], rig


# ----------------------------------------------------------------------------- helpers


def test_reordered_quaternions_undo_a_file_written_in_the_other_order() -> None:
    rng = np.random.default_rng(0)
    q = rng.normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)  # (x, y, z, w)
    T = se3.transforms_from_rt(se3.matrix_from_quat_xyzw(q), rng.normal(size=(20, 3)))
    # written w x y z, read as x y z w
    misread = se3.matrix_from_quat_xyzw(np.roll(q, 1, axis=1))
    np.testing.assert_allclose(reordered_quaternions(T, 1)[:, :3, :3], misread, atol=1e-12)
    fixed = reordered_quaternions(se3.transforms_from_rt(misread, T[:, :3, 3]), -1)
    np.testing.assert_allclose(fixed, T, atol=1e-12)
    # written x y z w, read as w x y z: the other roll
    np.testing.assert_allclose(
        reordered_quaternions(reordered_quaternions(T, -1), 1), T, atol=1e-12
    )


def test_length_scale_is_the_joint_distance_or_a_tenth_of_the_travel() -> None:
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, 0, 3] = [-3.0, -1.0, 1.0, 3.0]  # RMS travel sqrt(5)
    assert length_scale(np.array([0.0, 0.3, 0.4]), T) == pytest.approx(0.5)
    assert length_scale(np.array([0.0, 0.0, 0.1]), T) == pytest.approx(0.1 * np.sqrt(5.0))
    # two cameras: the larger, A's in B's units
    o = np.array([0.0, 0.0, 0.4])
    assert pair_length_scale(T, T, o, 0.5 * o, phi_ba=2.0) == pytest.approx(0.8)


def test_expected_residual_rms_matches_the_simulated_noise() -> None:
    rng = np.random.default_rng(1)
    rig = make_rig(rng, (0.1, 0.5))
    seq = fixed_joint_sequence(rng, rig, 4000)
    T = add_pose_noise(rng, seq.T_wa_a, 1.0, 0.004)
    assert seq.joint_in_world_a is not None
    r = se3.transform_points(T, rig.o_a) - seq.joint_in_world_a
    rms = float(np.sqrt(np.mean(np.sum(r**2, axis=1))))
    assert rms == pytest.approx(expected_residual_rms(1.0, 0.004, rig.o_a), rel=0.03)


def test_fit_is_suspicious_against_the_scale_or_the_stated_noise() -> None:
    assert not fit_is_suspicious(0.9 * SUSPICIOUS_FRACTION * 0.2, 0.2)
    assert fit_is_suspicious(1.1 * SUSPICIOUS_FRACTION * 0.2, 0.2)
    assert not fit_is_suspicious(0.004, 0.2, expected_rms=0.003)
    assert fit_is_suspicious(0.004, 0.2, expected_rms=0.001)


# ----------------------------------------------------------------------------- fixed joint


@pytest.mark.parametrize(
    ("shift", "cause"), [(1, "quaternion_order_wxyz"), (-1, "quaternion_order_xyzw")]
)
def test_fixed_joint_quaternion_order_is_named(fixed, shift: int, cause: str) -> None:
    T_true = fixed[0]
    T = reordered_quaternions(T_true, shift)
    rms = estimate_pivot(T, "refined", "camera A").residual_rms
    clean = estimate_pivot(T_true, "refined", "camera A").residual_rms
    d = diagnose_fixed_joint(T, quaternion_source=True, current_rms=rms)
    assert d is not None
    assert (d.cause, d.input) == (cause, "a")
    assert d.rms_after == pytest.approx(clean, rel=1e-6)
    assert d.rms_before == rms > 5 * d.rms_after
    assert "w-x-y-z" in d.message and f"{1e3 * rms:.3g} mm" in d.message


def test_fixed_joint_clean_or_not_from_quaternions_gives_none(fixed) -> None:
    T = fixed[1]
    rms = estimate_pivot(T, "refined", "camera B").residual_rms
    assert diagnose_fixed_joint(T, quaternion_source=True, current_rms=rms, camera="b") is None
    bad = reordered_quaternions(T, 1)
    rms_bad = estimate_pivot(bad, "refined", "camera B").residual_rms
    assert diagnose_fixed_joint(bad, quaternion_source=False, current_rms=rms_bad) is None


# ----------------------------------------------------------------------------- overlap


def test_overlap_names_the_camera_whose_quaternions_are_misread() -> None:
    rng = np.random.default_rng(3)
    seq = general_sequence(rng, make_rig(rng, (0.1, 0.5)), 40, shared_world=True)
    Ta, Tb = _noisy(rng, seq.T_wa_a), _noisy(rng, seq.T_wb_b)
    clean = estimate_joint_overlap(Ta, Tb).residual_rms["ab"]
    assert diagnose_overlap(Ta, Tb, quaternion_source=(True, True), current_rms=clean) is None
    bad = reordered_quaternions(Tb, 1)
    rms = estimate_joint_overlap(Ta, bad).residual_rms["ab"]
    d = diagnose_overlap(Ta, bad, quaternion_source=(True, True), current_rms=rms)
    assert d is not None and (d.cause, d.input) == ("quaternion_order_wxyz", "b")
    assert d.rms_after == pytest.approx(clean, rel=1e-6)
    # B's poses not from quaternions: its order is not suspected
    d2 = diagnose_overlap(Ta, bad, quaternion_source=(True, False), current_rms=rms)
    assert d2 is None or d2.cause != "quaternion_order_wxyz"


# ----------------------------------------------------------------------------- relpose


def _relpose_cases(Ta, Tb, prior, other):
    inv = se3.invert_transforms
    return {
        "A wxyz": (reordered_quaternions(Ta, 1), Tb, prior, ("quaternion_order_wxyz", "a")),
        "both inverted": (inv(Ta), inv(Tb), prior, ("inverted_poses", "ab")),
        "B inverted": (Ta, inv(Tb), prior, ("inverted_poses", "b")),
        "joint in mm": (Ta, Tb, scaled_prior(prior, 1e3), ("units_mm_vs_m", "joint")),
        "another rig": (Ta, Tb, other, ("joint_from_another_rig", "joint")),
    }


@pytest.mark.parametrize(
    "case", ["A wxyz", "both inverted", "B inverted", "joint in mm", "another rig"]
)
def test_relpose_cause_is_named(general, case: str) -> None:
    Ta, Tb, prior, other, _ = general
    A, B, p, expected = _relpose_cases(Ta, Tb, prior, other)[case]
    rms = estimate_relpose(A, B, p).residual_rms
    d = diagnose_relpose(A, B, p, current_rms=rms)
    assert d is not None
    assert (d.cause, d.input) == expected
    assert d.rms_after < MUCH_BETTER * rms
    clean = estimate_relpose(Ta, Tb, prior).residual_rms
    assert d.rms_after < 1.5 * clean


def test_relpose_another_rig_reports_the_distance_in_sigmas(general) -> None:
    Ta, Tb, _, other, _ = general
    d = diagnose_relpose(Ta, Tb, other, current_rms=estimate_relpose(Ta, Tb, other).residual_rms)
    assert d is not None and d.details["sigma_a"] > 10 and d.details["sigma_b"] > 10
    assert "sigma in A" in d.message and "--self-calibrate" in d.message


def test_relpose_units_message_says_which_way(general) -> None:
    Ta, Tb, prior, _, _ = general
    A = scale_translations(Ta, 1e3)
    d = diagnose_relpose(A, Tb, prior, current_rms=estimate_relpose(A, Tb, prior).residual_rms)
    assert d is not None and (d.cause, d.input) == ("units_mm_vs_m", "a")
    assert d.details["factor"] == pytest.approx(1e-3)
    assert "1000 times too large" in d.message


def test_relpose_clean_gives_none(general) -> None:
    Ta, Tb, prior, _, _ = general
    rms = estimate_relpose(Ta, Tb, prior).residual_rms
    assert diagnose_relpose(Ta, Tb, prior, current_rms=rms) is None


def test_relpose_noisy_but_clean_gives_none() -> None:
    """A fit made suspicious by plain noise (5 mm on a joint 0.1 m away) names nothing."""
    rng = np.random.default_rng(5)
    rig = make_rig(rng, (0.1, 0.12))
    s = fixed_joint_sequence(rng, rig, 40)
    j = estimate_joint_fixed(
        add_pose_noise(rng, s.T_wa_a, 1.0, 0.005), add_pose_noise(rng, s.T_wb_b, 1.0, 0.005)
    )
    prior = JointPrior(j.position_in_a, j.position_in_b, j.covariance_a, j.covariance_b)
    seq = general_sequence(rng, rig, 40)
    Ta = add_pose_noise(rng, seq.T_wa_a, 1.0, 0.005)
    Tb = add_pose_noise(rng, seq.T_wb_b, 1.0, 0.005)
    est = estimate_relpose(Ta, Tb, prior)
    scale = pair_length_scale(Ta, Tb, est.position_in_a, est.position_in_b)
    assert fit_is_suspicious(est.residual_rms, scale)
    assert diagnose_relpose(Ta, Tb, prior, current_rms=est.residual_rms) is None


def test_relpose_unsynchronised_clocks_are_named(general) -> None:
    _, _, prior, _, rig = general
    rng = np.random.default_rng(11)
    seq = smooth_general_sequence(rng, rig, 80, fps=10.0, time_offset_s=0.2)
    Ta, Tb = _noisy(rng, seq.T_wa_a), _noisy(rng, seq.T_wb_b)
    timed = TimedPair(seq.timestamps, Ta, seq.timestamps, Tb)
    rms = estimate_relpose(Ta, Tb, prior).residual_rms
    d = diagnose_relpose(Ta, Tb, prior, current_rms=rms, timed=timed, max_offset=0.3)
    assert d is not None and (d.cause, d.input) == ("unsynchronised", "ab")
    assert d.details["offset_s"] == pytest.approx(0.2, abs=0.01)
    assert "--estimate-time-offset" in d.message


def test_relpose_clocks_of_a_short_recording_are_checked_a_frame_at_a_time(general) -> None:
    """35 frames at 10 Hz are too few for the offset search: shifts of a frame tell."""
    _, _, prior, _, rig = general
    rng = np.random.default_rng(12)
    seq = smooth_general_sequence(
        rng, rig, 35, fps=10.0, time_offset_s=0.1, max_rotation_deg=30.0, translation_range=2.0
    )
    Ta, Tb = _noisy(rng, seq.T_wa_a), _noisy(rng, seq.T_wb_b)
    timed = TimedPair(seq.timestamps, Ta, seq.timestamps, Tb)
    rms = estimate_relpose(Ta, Tb, prior).residual_rms
    d = diagnose_relpose(Ta, Tb, prior, current_rms=rms, timed=timed)
    assert d is not None and (d.cause, d.input) == ("unsynchronised", "ab")
    assert d.details["offset_s"] == pytest.approx(0.1, abs=1e-9)


def test_paper_method_misfit_names_the_method_only_when_the_refined_fit_is_much_better() -> None:
    found = paper_method_misfit(0.3, 0.01, "ab", "m")
    assert found is not None and found.cause == "paper_method_outliers"
    assert "--method refined" in found.message and "10 mm against 300 mm" in found.message
    assert paper_method_misfit(0.3, 0.2, "ab", "m") is None
