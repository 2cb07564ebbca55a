"""Frame pairing by index and by timestamp."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis_profiles import examples

from acs_cli.core.pairing import (
    default_max_dt,
    pair_by_index,
    pair_by_timestamp,
    pair_trajectories,
)
from acs_cli.errors import InputError
from acs_cli.io.trajectory import Trajectory


def _traj(t: np.ndarray, has_timestamps: bool = True, source: str = "x") -> Trajectory:
    T = np.broadcast_to(np.eye(4), (len(t), 4, 4)).copy()
    return Trajectory(np.asarray(t, float), T, source, "tum", has_timestamps)


def test_pair_by_index() -> None:
    r = pair_by_index(5, 3)
    assert r.idx_a.tolist() == [0, 1, 2] and r.idx_b.tolist() == [0, 1, 2]
    assert (r.unpaired_a, r.unpaired_b, r.max_dt, r.n_pairs) == (2, 0, None, 3)
    r = pair_by_index(0, 4)
    assert r.n_pairs == 0 and r.unpaired_b == 4


def test_jittered_timestamps(rng: np.random.Generator) -> None:
    n = 200
    t_a = np.arange(n) / 30.0
    t_b = t_a + rng.uniform(-0.005, 0.005, n) + 0.002
    r = pair_by_timestamp(t_a, t_b)
    assert r.max_dt == pytest.approx(min(np.median(np.diff(t_a)), np.median(np.diff(t_b))) / 2)
    assert r.idx_a.tolist() == list(range(n))
    assert r.idx_b.tolist() == list(range(n))
    assert r.unpaired_a == 0 and r.unpaired_b == 0


def test_dropped_frames_on_either_side(rng: np.random.Generator) -> None:
    n = 300
    base = np.arange(n) / 20.0
    drop_a = rng.choice(n, 17, replace=False)
    drop_b = rng.choice(n, 9, replace=False)
    keep_a = np.setdiff1d(np.arange(n), drop_a)
    keep_b = np.setdiff1d(np.arange(n), drop_b)
    t_a = base[keep_a] + rng.uniform(-0.004, 0.004, keep_a.size)
    t_b = base[keep_b] + rng.uniform(-0.004, 0.004, keep_b.size)
    r = pair_by_timestamp(t_a, t_b)
    common = np.intersect1d(keep_a, keep_b)
    assert r.n_pairs == common.size
    np.testing.assert_array_equal(keep_a[r.idx_a], common)
    np.testing.assert_array_equal(keep_b[r.idx_b], common)
    assert r.unpaired_a == keep_a.size - common.size
    assert r.unpaired_b == keep_b.size - common.size
    assert np.all(np.abs(t_a[r.idx_a] - t_b[r.idx_b]) <= r.max_dt)


def test_max_dt_respected() -> None:
    t_a = np.array([0.0, 1.0, 2.0, 3.0])
    t_b = np.array([0.05, 1.2, 2.4, 3.01])
    r = pair_by_timestamp(t_a, t_b, max_dt=0.1)
    assert r.idx_a.tolist() == [0, 3] and r.idx_b.tolist() == [0, 3]
    assert (r.unpaired_a, r.unpaired_b) == (2, 2)
    r = pair_by_timestamp(t_a, t_b, max_dt=0.25)
    assert r.idx_a.tolist() == [0, 1, 3]
    r = pair_by_timestamp(t_a, t_b, max_dt=0.0)
    assert r.n_pairs == 0
    assert pair_by_timestamp([1.0], [1.0], max_dt=0.0).n_pairs == 1


def test_one_to_one_closest_first() -> None:
    # two A frames compete for one B frame: the closer wins, the other stays unpaired
    r = pair_by_timestamp([0.0, 0.3], [0.25], max_dt=1.0)
    assert r.idx_a.tolist() == [1] and r.idx_b.tolist() == [0]
    assert (r.unpaired_a, r.unpaired_b) == (1, 0)
    # a second round pairs a frame with its second-nearest partner
    r = pair_by_timestamp([0.0, 0.5], [0.3, 0.45], max_dt=1.0)
    assert sorted(zip(r.idx_a.tolist(), r.idx_b.tolist(), strict=True)) == [(0, 0), (1, 1)]


def test_unsorted_input() -> None:
    r = pair_by_timestamp([3.0, 1.0, 2.0], [2.01, 0.99, 3.02])
    assert r.idx_a.tolist() == [0, 1, 2]
    assert r.idx_b.tolist() == [2, 1, 0]


def test_default_max_dt_degenerate() -> None:
    assert default_max_dt([1.0], [2.0]) == np.inf
    assert default_max_dt([1.0], [0.0, 0.2, 0.4]) == pytest.approx(0.1)


def test_bad_input() -> None:
    with pytest.raises(InputError, match="max_dt"):
        pair_by_timestamp([0.0], [0.0], max_dt=-1.0)
    with pytest.raises(InputError, match="max_dt"):
        pair_by_timestamp([0.0], [0.0], max_dt=float("nan"))
    with pytest.raises(InputError, match="NaN"):
        pair_by_timestamp([np.nan], [0.0])


def _greedy(t_a: list[float], t_b: list[float], max_dt: float) -> set[tuple[int, int]]:
    cands = sorted(
        (abs(a - b), i, j)
        for (i, a), (j, b) in itertools.product(enumerate(t_a), enumerate(t_b))
        if abs(a - b) <= max_dt
    )
    used_a: set[int] = set()
    used_b: set[int] = set()
    out = set()
    for _, i, j in cands:
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            out.add((i, j))
    return out


@settings(max_examples=examples(200))
@given(
    t_a=st.lists(st.integers(0, 1000), min_size=1, max_size=12, unique=True),
    t_b=st.lists(st.integers(0, 1000), min_size=1, max_size=12, unique=True),
    max_dt=st.integers(0, 300),
)
def test_matches_greedy_reference(t_a: list[int], t_b: list[int], max_dt: int) -> None:
    # distinct distances (ties are broken differently but are equally valid): scale by a
    # transcendental-ish factor plus a per-sample offset
    fa = [x + 1e-6 * np.sqrt(2) * k for k, x in enumerate(t_a)]
    fb = [x + 1e-6 * np.sqrt(3) * k + 0.5 for k, x in enumerate(t_b)]
    r = pair_by_timestamp(fa, fb, max_dt=max_dt)
    got = set(zip(r.idx_a.tolist(), r.idx_b.tolist(), strict=True))
    assert got == _greedy(fa, fb, max_dt)
    assert r.unpaired_a == len(fa) - len(got)
    assert r.unpaired_b == len(fb) - len(got)


def test_pair_trajectories() -> None:
    a = _traj(np.arange(10) / 10.0, source="a.txt")
    b = _traj(np.arange(2, 12) / 10.0 + 0.01, source="b.txt")
    r = pair_trajectories(a, b)
    assert r.idx_a.tolist() == list(range(2, 10))
    assert r.idx_b.tolist() == list(range(8))
    k = _traj(np.arange(6.0), has_timestamps=False)
    r = pair_trajectories(a, k)
    assert r.max_dt is None and r.n_pairs == 6
    r = pair_trajectories(a, b, by="index")
    assert r.n_pairs == 10
    with pytest.raises(InputError, match="has no timestamps"):
        pair_trajectories(a, k, by="timestamp")
    with pytest.raises(InputError, match="unknown pairing"):
        pair_trajectories(a, b, by="name")


def test_no_common_timestamps() -> None:
    a = _traj(np.arange(10) / 10.0, source="a.txt")
    b = _traj(100 + np.arange(10) / 10.0, source="b.txt")
    with pytest.raises(InputError, match=r"no common timestamps between a.txt .* b.txt"):
        pair_trajectories(a, b)


def test_unevenly_spaced_samples_of_one_camera_never_share_a_slot() -> None:
    # a subsampled sequence (frames 7, 8, 11: median interval 2) lost frame 8 to frame 7's
    # slot with the default max_dt of half the median interval
    from acs_cli.core.pairing import common_timeline

    slots, index = common_timeline({"l": [7.0, 8.0, 11.0], "r": [7.0, 8.0, 11.0]})
    np.testing.assert_array_equal(slots, [7.0, 8.0, 11.0])
    np.testing.assert_array_equal(index["l"], [0, 1, 2])
    slots, index = common_timeline({"l": [0.0, 1.0, 3.0, 5.0], "r": [0.0, 1.0, 3.0, 5.0]})
    assert slots.size == 4 and (index["r"] >= 0).all()
