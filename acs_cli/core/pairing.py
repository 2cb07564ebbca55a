"""Pair the frames of two trajectories by index or by nearest timestamp.

Pure functions of arrays; :func:`pair_trajectories` applies them to two
:class:`~acs_cli.io.trajectory.Trajectory` objects.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acs_cli.errors import InputError

if TYPE_CHECKING:
    from acs_cli.io.trajectory import Trajectory

__all__ = [
    "PAIR_BY",
    "PairingResult",
    "common_timeline",
    "default_max_dt",
    "pair_by_index",
    "pair_by_timestamp",
    "pair_trajectories",
]

IntArray = NDArray[np.intp]

#: Values of ``by`` that :func:`pair_trajectories` accepts.
PAIR_BY = ("auto", "timestamp", "index")


@dataclass(frozen=True, eq=False)
class PairingResult:
    """Matched frames of two sequences A and B.

    Attributes
    ----------
    idx_a, idx_b : ndarray of int, shape (m,)
        Pair ``k`` is frame ``idx_a[k]`` of A with frame ``idx_b[k]`` of B; ``idx_a`` is
        increasing and each frame appears at most once.
    unpaired_a, unpaired_b : int
        Number of frames of A (of B) left without a partner.
    max_dt : float or None
        The largest accepted ``|t_a - t_b|`` (seconds), or None for index pairing.
    """

    idx_a: IntArray
    idx_b: IntArray
    unpaired_a: int
    unpaired_b: int
    max_dt: float | None

    @property
    def n_pairs(self) -> int:
        """Number of pairs ``m``."""
        return int(self.idx_a.shape[0])


def pair_by_index(n_a: int, n_b: int) -> PairingResult:
    """Pair frame ``i`` of A with frame ``i`` of B over the common prefix.

    Parameters
    ----------
    n_a, n_b : int
        Numbers of frames.

    Returns
    -------
    PairingResult
        ``idx_a = idx_b = 0..min(n_a, n_b)-1``; ``max_dt`` is None.
    """
    m = max(0, min(int(n_a), int(n_b)))
    idx = np.arange(m, dtype=np.intp)
    return PairingResult(idx, idx.copy(), int(n_a) - m, int(n_b) - m, None)


def _as_times(t: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(t, dtype=float)
    if arr.ndim != 1:
        raise InputError(f"{name} must have shape (n,), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    return arr


def _median_interval(t: NDArray[np.float64]) -> float:
    if t.shape[0] < 2:
        return float("inf")
    with np.errstate(over="ignore", invalid="ignore"):
        return float(np.median(np.diff(np.sort(t))))


def _smallest_gap(t: NDArray[np.float64]) -> float:
    """The smallest positive interval between a camera's samples (``inf`` if none)."""
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.diff(np.sort(t))
    d = d[d > 0]
    return float(d.min()) if d.size else float("inf")


def default_max_dt(t_a: ArrayLike, t_b: ArrayLike) -> float:
    """Half the smaller of the two median frame intervals (seconds).

    A sequence with fewer than two frames has no interval; if neither has one, the result
    is ``inf`` (any pair is accepted).
    """
    ta = _as_times(t_a, "t_a")
    tb = _as_times(t_b, "t_b")
    return min(_median_interval(ta), _median_interval(tb)) / 2.0


def _nearest(sorted_vals: NDArray[np.float64], q: NDArray[np.float64]) -> IntArray:
    """Index into ``sorted_vals`` (ascending, non-empty) of each query's nearest value.

    Ties go to the smaller value.
    """
    n = sorted_vals.shape[0]
    j = np.searchsorted(sorted_vals, q)
    left = np.clip(j - 1, 0, n - 1)
    right = np.clip(j, 0, n - 1)
    with np.errstate(over="ignore", invalid="ignore"):
        d_left = np.where(j > 0, np.abs(q - sorted_vals[left]), np.inf)
        d_right = np.where(j < n, np.abs(sorted_vals[right] - q), np.inf)
    return np.where(d_left <= d_right, left, right).astype(np.intp)


def pair_by_timestamp(t_a: ArrayLike, t_b: ArrayLike, max_dt: float | None = None) -> PairingResult:
    """Match frames one-to-one by nearest timestamp, closest pairs first.

    The result equals greedy matching: repeatedly take the closest remaining pair
    ``(i, j)`` with ``|t_a[i] - t_b[j]| <= max_dt`` and remove both frames. It is computed
    as rounds of mutual-nearest-neighbour matching among the remaining frames (vectorised
    with ``np.searchsorted``); usually one or two rounds suffice.

    Parameters
    ----------
    t_a : array_like, shape (n_a,)
        Timestamps of A (seconds; any order).
    t_b : array_like, shape (n_b,)
        Timestamps of B, same clock.
    max_dt : float, optional
        Largest accepted time difference (seconds). Default: :func:`default_max_dt`, half
        the smaller median frame interval.

    Returns
    -------
    PairingResult
        Pairs sorted by ``idx_a``; possibly none.

    Raises
    ------
    InputError
        Timestamps not 1-D or not finite; ``max_dt`` negative or NaN.
    """
    ta = _as_times(t_a, "t_a")
    tb = _as_times(t_b, "t_b")
    limit = default_max_dt(ta, tb) if max_dt is None else float(max_dt)
    if not limit >= 0:
        raise InputError(f"max_dt must be a non-negative number of seconds, got {max_dt!r}")
    order_a = np.argsort(ta, kind="stable")
    order_b = np.argsort(tb, kind="stable")
    sa, sb = ta[order_a], tb[order_b]
    free_a = np.arange(sa.shape[0], dtype=np.intp)  # positions into sa still unmatched
    free_b = np.arange(sb.shape[0], dtype=np.intp)
    got_a: list[IntArray] = []
    got_b: list[IntArray] = []
    while free_a.size and free_b.size:
        va, vb = sa[free_a], sb[free_b]
        nn_ab = _nearest(vb, va)  # for each free a: position in free_b
        nn_ba = _nearest(va, vb)  # for each free b: position in free_a
        ka = np.arange(free_a.size)
        with np.errstate(over="ignore", invalid="ignore"):
            close = np.abs(va - vb[nn_ab]) <= limit
        mutual = (nn_ba[nn_ab] == ka) & close
        if not mutual.any():
            break
        pa, pb = ka[mutual], nn_ab[mutual]
        got_a.append(free_a[pa])
        got_b.append(free_b[pb])
        # Frames whose nearest free partner is beyond max_dt can never be matched.
        keep_a = ~mutual & close
        with np.errstate(over="ignore", invalid="ignore"):
            close_b = np.abs(vb - va[nn_ba]) <= limit
        keep_b = np.ones(free_b.size, dtype=bool)
        keep_b[pb] = False
        keep_b &= close_b
        free_a, free_b = free_a[keep_a], free_b[keep_b]
    if got_a:
        ia = order_a[np.concatenate(got_a)]
        ib = order_b[np.concatenate(got_b)]
        srt = np.argsort(ia, kind="stable")
        ia, ib = ia[srt].astype(np.intp), ib[srt].astype(np.intp)
    else:
        ia = np.zeros(0, dtype=np.intp)
        ib = np.zeros(0, dtype=np.intp)
    return PairingResult(ia, ib, ta.shape[0] - ia.shape[0], tb.shape[0] - ib.shape[0], limit)


def pair_trajectories(
    traj_a: Trajectory, traj_b: Trajectory, by: str = "auto", max_dt: float | None = None
) -> PairingResult:
    """Pair the frames of two trajectories.

    Parameters
    ----------
    traj_a, traj_b : Trajectory
        Camera A's and camera B's trajectories.
    by : {"auto", "timestamp", "index"}
        ``"auto"``: by timestamp when both have timestamps, else by index.
    max_dt : float, optional
        For timestamp pairing: the largest accepted time difference in seconds (default
        half the smaller median frame interval).

    Returns
    -------
    PairingResult
        At least one pair.

    Raises
    ------
    InputError
        An unknown ``by``; timestamp pairing asked for a trajectory without timestamps; no
        common timestamps.
    """
    if by not in PAIR_BY:
        raise InputError(f"unknown pairing {by!r}; use one of {', '.join(PAIR_BY)}")
    use_time = by == "timestamp" or (
        by == "auto" and traj_a.has_timestamps and traj_b.has_timestamps
    )
    if not use_time:
        return pair_by_index(len(traj_a), len(traj_b))
    for traj in (traj_a, traj_b):
        if not traj.has_timestamps:
            raise InputError(
                f"has no timestamps ({traj.format} file); pair by index instead",
                path=traj.source,
            )
    if traj_a.time_unit != traj_b.time_unit:
        frames = traj_a if traj_a.time_unit == "frame" else traj_b
        raise InputError(
            "has frame numbers for times, the other trajectory seconds: give both in seconds "
            "(`acscal poses --fps` or `--timestamps`, or a TUM file with times)",
            path=frames.source,
        )
    result = pair_by_timestamp(traj_a.timestamps, traj_b.timestamps, max_dt)
    if result.n_pairs == 0:
        ta, tb = traj_a.timestamps, traj_b.timestamps
        raise InputError(
            f"no common timestamps between {traj_a.source} ({ta[0]:.6f}..{ta[-1]:.6f} s) and "
            f"{traj_b.source} ({tb[0]:.6f}..{tb[-1]:.6f} s) within max_dt = "
            f"{result.max_dt:.6g} s; are both on the same clock?"
        )
    return result


def common_timeline(
    times: dict[str, ArrayLike], max_dt: float | None = None
) -> tuple[NDArray[np.float64], dict[str, IntArray]]:
    """Put every camera's samples on one timeline (a rig's cameras, paired all at once).

    Samples of all cameras are sorted together and grouped: a group (a *slot*) starts at a
    sample more than ``max_dt`` after the sample before it. Each camera contributes at most
    its sample nearest the slot's time (the slot's first sample), within ``max_dt``.

    Parameters
    ----------
    times : dict of str to array, shape (n_c,)
        Each camera's increasing timestamps (seconds).
    max_dt : float, optional
        Largest spread of one slot; default half the smallest median frame interval, and
        below every camera's smallest interval (two samples of one camera never share a
        slot).

    Returns
    -------
    slot_times : ndarray, shape (m,)
    index : dict of str to ndarray of int, shape (m,)
        For each camera, its sample in each slot, or -1.
    """
    ts = {c: _as_times(t, f"times[{c}]") for c, t in times.items()}
    if max_dt is None:
        intervals = [_median_interval(t) for t in ts.values()]
        max_dt = min(intervals) / 2.0 if intervals else float("inf")
        # never one slot for two samples of one camera: an unevenly spaced sequence
        # (subsampled, dropped frames) has gaps below the median interval
        gaps = [_smallest_gap(t) for t in ts.values()]
        max_dt = min([max_dt, *(0.99 * g for g in gaps)])
    if not np.isfinite(max_dt):
        max_dt = float("inf")
    allt = np.sort(np.concatenate([t for t in ts.values()] or [np.zeros(0)]))
    starts = np.ones(allt.shape[0], dtype=bool)
    with np.errstate(invalid="ignore"):
        starts[1:] = np.diff(allt) > max_dt
    slot_times = allt[starts]
    index: dict[str, IntArray] = {}
    for c, t in ts.items():
        idx = np.full(slot_times.shape[0], -1, dtype=np.intp)
        if t.size and slot_times.size:
            # each sample to its slot (the last slot starting at or before it)
            s = np.clip(np.searchsorted(slot_times, t, side="right") - 1, 0, None)
            d = np.abs(t - slot_times[s])
            order = np.lexsort((d, s))  # by slot, nearest first
            first = np.ones(order.size, dtype=bool)
            first[1:] = s[order][1:] != s[order][:-1]
            keep = order[first]
            keep = keep[d[keep] <= max_dt]
            idx[s[keep]] = keep
        index[c] = idx
    return slot_times, index
