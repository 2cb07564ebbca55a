"""A constant clock offset between two cameras, estimated with the calibration (issue 10)."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.relpose import JointPrior, estimate_relpose
from acs_cli.core.rig_solve import TEST_SETTLED_NOISE
from acs_cli.core.time_offset import (
    COARSE_FRAMES,
    PoseInterpolator,
    PoseSmoother,
    estimate_time_offset,
    gaussian_profile_cost,
    synchronisation_check,
)
from acs_cli.errors import DegenerateMotionError, InputError
from sample_data_gen.acs_sim import add_pose_noise, make_rig, smooth_general_sequence


def _fit(Ta: np.ndarray, Tb: np.ndarray) -> np.ndarray:
    # as `acscal relpose --estimate-time-offset` fits each pairing (stages/relpose.py): every
    # frame kept, the noise levels settled to 2%
    return estimate_relpose(
        Ta, Tb, reject_outliers=False, noise_tolerance=TEST_SETTLED_NOISE
    ).residuals


def _recording(seed: int, offset: float, n: int = 300) -> tuple:
    rng = np.random.default_rng(seed)
    seq = smooth_general_sequence(rng, make_rig(rng), n, time_offset_s=offset)
    Ta = add_pose_noise(rng, seq.T_wa_a, 0.1, 0.005)
    Tb = add_pose_noise(rng, seq.T_wb_b, 0.1, 0.005)
    return seq, Ta, Tb


def test_interpolation_passes_through_the_samples_and_follows_smooth_motion() -> None:
    rng = np.random.default_rng(0)
    seq = smooth_general_sequence(rng, make_rig(rng), 200, fps=30.0)
    t = seq.timestamps
    interp = PoseInterpolator(t[::2], seq.T_wa_a[::2])
    np.testing.assert_allclose(interp(t[::2]), seq.T_wa_a[::2], atol=1e-9)
    mid = interp(t[1:-1:2])  # the skipped samples, from their neighbours at 15 Hz
    ang = se3.rotation_angle_deg(
        np.matmul(np.swapaxes(mid[:, :3, :3], 1, 2), seq.T_wa_a[1:-1:2, :3, :3])
    )
    # away from the ends (where a spline has only one side), far below any pose noise
    assert float(np.max(ang[3:-3])) < 0.005 and float(np.max(ang)) < 0.2
    err = np.linalg.norm(mid[:, :3, 3] - seq.T_wa_a[1:-1:2, :3, 3], axis=1)
    assert float(np.max(err[3:-3])) < 1e-4
    assert not interp.valid(np.array([t[0] - 0.01, t[-1] + 0.01])).any()
    gap = PoseInterpolator(
        np.delete(t, np.arange(50, 60)), np.delete(seq.T_wa_a, np.arange(50, 60), 0)
    )
    assert not gap.valid(np.array([t[55]]))[0] and gap.valid(np.array([t[40]]))[0]
    with pytest.raises(InputError, match="increasing"):
        PoseInterpolator(t[::-1], seq.T_wa_a)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_37_ms_offset_is_found_within_a_millisecond(seed: int) -> None:
    seq, Ta, Tb = _recording(seed, 0.037, n=160)
    t = seq.timestamps
    off = estimate_time_offset(t, Ta, t, Tb, _fit, 0.1)
    assert abs(off.offset_s - 0.037) < 1e-3, off.offset_s
    assert 0 < off.std_s < 2e-3 and abs(off.offset_s - 0.037) < 4 * off.std_s
    assert not off.at_limit and off.frames.sum() > 130
    assert off.profile.shape[1] == 2 and np.argmin(off.profile[:, 1]) > 0


def test_an_offset_beyond_the_range_is_at_its_limit() -> None:
    seq, Ta, Tb = _recording(2, 0.15)
    t = seq.timestamps
    off = estimate_time_offset(t, Ta, t, Tb, _fit, 0.05)
    assert off.at_limit


@pytest.mark.parametrize("failures", [1, 10**6])
def test_offsets_where_the_calibration_fails_do_not_upset_the_refinement(failures: int) -> None:
    # the first `failures` calibrations on all the frames (the refinement's, not the
    # grid's on COARSE_FRAMES) fail: an infinite cost made Brent's step NaN, with a
    # RuntimeWarning from SciPy (a real knee recording); all failing leave the grid's minimum
    seq, Ta, Tb = _recording(0, 0.037)
    calls = []

    def holey_fit(A: np.ndarray, B: np.ndarray) -> np.ndarray:
        if len(A) > COARSE_FRAMES:
            calls.append(len(A))
            if len(calls) <= failures:
                raise DegenerateMotionError("not at this offset")
        return _fit(A, B)

    t = seq.timestamps
    off = estimate_time_offset(t, Ta, t, Tb, holey_fit, 0.2)
    step = float(off.profile[1, 0] - off.profile[0, 0])
    assert abs(off.offset_s - 0.037) < (1e-3 if failures == 1 else step)
    assert np.isfinite(off.std_s) == (failures == 1)


def test_synchronisation_check_flags_an_offset_and_not_a_synchronised_pair() -> None:
    seq, Ta, Tb = _recording(3, 0.0)
    t = seq.timestamps
    assert synchronisation_check(t, Ta, t, Tb, _fit) is None
    seq, Ta, Tb = _recording(3, 0.037)
    found = synchronisation_check(seq.timestamps, Ta, seq.timestamps, Tb, _fit)
    assert found is not None and found[0] > 0 and found[1] < 0.9


def test_too_short_an_overlap_is_refused() -> None:
    seq, Ta, Tb = _recording(4, 0.0, n=40)
    t = seq.timestamps
    with pytest.raises(DegenerateMotionError, match="overlap"):
        estimate_time_offset(t, Ta, t + 1.0, Tb, _fit, 0.2)
    with pytest.raises(InputError, match="positive"):
        estimate_time_offset(t, Ta, t, Tb, _fit, 0.0)


def test_gaussian_profile_cost_is_the_isotropic_likelihood() -> None:
    r = np.ones((10, 3))
    assert gaussian_profile_cost(r) == pytest.approx(0.0)
    assert gaussian_profile_cost(2 * r) == pytest.approx(15 * np.log(4.0))


def _noise_gain(smoother: type, s: float) -> float:
    """``sum_j l_j^2`` of a linear pose smoother or interpolator at a fraction ``s`` of a frame
    between samples, from its response to unit translations of one sample at a time."""
    n = 60
    t = np.arange(n) / 30.0
    q = np.array([t[30] + s / 30.0])
    gain = 0.0
    for j in range(20, 41):
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        T[j, 0, 3] = 1.0
        gain += float(smoother(t, T)(q)[0, 0, 3]) ** 2
    return gain


def test_smoothing_has_one_noise_gain_at_every_fraction_of_a_frame() -> None:
    """The cause of the time offset's bias: a cubic spline through noisy poses passes one noisy
    sample on a frame and averages two half-way (a noise gain of 1 against 0.76), so the
    fitted noise, and the cost, ripple with the frame period; the search's smoother does not."""
    fractions = np.linspace(0.0, 1.0, 5)[:-1]
    spline = np.array([_noise_gain(PoseInterpolator, s) for s in fractions])
    assert spline[0] == pytest.approx(1.0) and spline[2] < 0.8
    smooth = np.array([_noise_gain(PoseSmoother, s) for s in fractions])
    np.testing.assert_allclose(smooth, 0.317, rtol=2e-3)
    assert np.ptp(smooth) < 1e-3 * smooth.mean()


def test_smoothing_keeps_smooth_motion_and_needs_samples_around() -> None:
    rng = np.random.default_rng(0)
    seq = smooth_general_sequence(rng, make_rig(rng), 200, fps=60.0)
    t = seq.timestamps
    smooth = PoseSmoother(t[::2], seq.T_wa_a[::2])  # 30 Hz, queried between and on samples
    q = t[1:-1]
    ok = smooth.valid(q)
    # a reach of 5 widths (7.5 frames at 30 Hz) on either side
    assert not ok[:14].any() and not ok[-14:].any() and ok[20:-20].all()
    out, truth = smooth(q[ok]), seq.T_wa_a[1:-1][ok]
    ang = se3.rotation_angle_deg(np.matmul(np.swapaxes(out[:, :3, :3], 1, 2), truth[:, :3, :3]))
    assert float(np.max(ang)) < 0.01  # far below any pose noise
    assert float(np.max(np.linalg.norm(out[:, :3, 3] - truth[:, :3, 3], axis=1))) < 1e-4
    gap = PoseSmoother(
        np.delete(t, np.arange(100, 104)), np.delete(seq.T_wa_a, np.arange(100, 104), 0)
    )
    assert not gap.valid(t[[95, 102, 108]]).any() and gap.valid(t[[60, 140]]).all()


def _offsets(offsets: tuple[float, ...], noise_seeds: range) -> np.ndarray:
    """Errors and stds (s), shape ``(len(offsets), len(noise_seeds), 2)``, of the offset
    estimated on one seeded smooth motion (150 frames at 30 Hz) with B's clock ``offsets``
    ahead, under pose noise 0.1 deg / 5 mm from each noise seed (the joint known, for speed)."""
    out = np.zeros((len(offsets), len(noise_seeds), 2))
    for i, offset in enumerate(offsets):
        for j, k in enumerate(noise_seeds):
            rng = np.random.default_rng(7)
            rig = make_rig(rng)
            seq = smooth_general_sequence(rng, rig, 150, time_offset_s=offset)
            noise = np.random.default_rng(100 + k)
            Ta = add_pose_noise(noise, seq.T_wa_a, 0.1, 0.005)
            Tb = add_pose_noise(noise, seq.T_wb_b, 0.1, 0.005)
            prior = JointPrior(rig.o_a, rig.o_b)

            def fit(A: np.ndarray, B: np.ndarray, prior: JointPrior = prior) -> np.ndarray:
                return estimate_relpose(A, B, prior, reject_outliers=False).residuals

            t = seq.timestamps
            off = estimate_time_offset(t, Ta, t, Tb, fit, 0.05)
            out[i, j] = off.offset_s - offset, off.std_s
    return out


def test_the_estimate_does_not_depend_on_the_offsets_fraction_of_a_frame() -> None:
    """The same motion and noise with B's clock 0.25 and 0.75 frame ahead: with the poses
    interpolated by a spline the two were pulled towards the half frame, in opposite
    directions (about 1 ms apart); smoothed, they err alike."""
    err = _offsets((0.25 / 30.0, 0.75 / 30.0), range(1))[:, 0, 0]
    assert abs(err[0] - err[1]) < 1e-4, err
    assert np.all(np.abs(err) < 2e-3)


@pytest.mark.slow
def test_the_std_matches_the_spread_over_noise() -> None:
    """One motion under ten noise draws: the reported std agrees with the errors' spread."""
    res = _offsets((0.75 / 30.0,), range(10))[0]
    err, std = res[:, 0], res[:, 1]
    assert 0.6 < float(np.sqrt(np.mean((err / std) ** 2))) < 1.5, (err, std)
    spread = float(np.sqrt(np.mean(err**2)))
    assert 0.6 < float(np.sqrt(np.mean(std**2))) / spread < 1.6, (err, std)
