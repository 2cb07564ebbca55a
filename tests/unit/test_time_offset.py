"""A constant clock offset between two cameras, estimated with the calibration (issue 10)."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.relpose import estimate_relpose
from acs_cli.core.time_offset import (
    PoseInterpolator,
    estimate_time_offset,
    gaussian_profile_cost,
    synchronisation_check,
)
from acs_cli.errors import DegenerateMotionError, InputError
from sample_data_gen.acs_sim import add_pose_noise, make_rig, smooth_general_sequence


def _fit(Ta: np.ndarray, Tb: np.ndarray) -> np.ndarray:
    return estimate_relpose(Ta, Tb, reject_outliers=False).residuals


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
    seq, Ta, Tb = _recording(seed, 0.037)
    t = seq.timestamps
    off = estimate_time_offset(t, Ta, t, Tb, _fit, 0.2)
    assert abs(off.offset_s - 0.037) < 1e-3, off.offset_s
    assert 0 < off.std_s < 2e-3 and abs(off.offset_s - 0.037) < 4 * off.std_s
    assert not off.at_limit and off.frames.sum() > 250
    assert off.profile.shape[1] == 2 and np.argmin(off.profile[:, 1]) > 0


def test_an_offset_beyond_the_range_is_at_its_limit() -> None:
    seq, Ta, Tb = _recording(2, 0.15)
    t = seq.timestamps
    off = estimate_time_offset(t, Ta, t, Tb, _fit, 0.05)
    assert off.at_limit


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
