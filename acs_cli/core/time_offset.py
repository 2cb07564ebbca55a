"""A constant time offset between two cameras' clocks, estimated with the calibration.

Convention: ``dt`` (``time_offset_s``) is what camera B's clock reads minus what camera
A's clock reads at the same instant. Camera A's pose stamped ``t`` is therefore paired with
camera B's pose at B's time ``t + dt``, interpolated on SE(3): a C2 rotation spline
(:class:`scipy.spatial.transform.RotationSpline`) and a cubic spline of the translations.
Only frames of A whose B-time falls between two B samples at most ``max_gap`` apart are
paired (no interpolation across gaps).

The estimate minimises a profile cost ``c(dt)``: for each ``dt`` the caller's estimator
calibrates the pair on the shifted pairing and returns its residuals, whose negative
log-likelihood (:func:`gaussian_profile_cost`) is the cost. The frames are fixed over the
whole search (those valid for every ``dt`` in ``[-max_offset, max_offset]``), so that costs
compare. A grid of steps of one frame interval is refined by a bounded Brent search between
the neighbours of its best point. (The poses are smoothed over 1.5 intervals, so the cost has
no structure finer than that: a grid of half intervals found the same minimum in the tests
and on a real knee, at twice the calibrations.)

The search pairs *smoothed* trajectories (:class:`PoseSmoother`), not interpolated ones.
Interpolating noisy poses changes their noise with the shift: on a frame the spline returns
one noisy sample, half-way it averages neighbours (a noise variance of 0.76x for a cubic
spline). The fitted noise level, and so the cost, would then ripple with the frame period and
pull ``dt`` towards the nearest half frame (by 0.5 ms on average, 2 ms at worst, at 30 Hz
under 0.1 deg / 5 mm of noise). A local quadratic regression with Gaussian weights 1.5 frame
intervals wide has the same noise gain (0.32) at every fraction of a frame to 1e-4 and keeps
smooth motion to thousandths of a degree; both cameras are smoothed alike. The calibration
itself is left to the caller, on the raw poses paired at the estimate.

The standard deviation is a sandwich estimate, ``sqrt(Var(c'(dt))) / c''(dt)`` (see
:func:`_sandwich_std`): ``1 / sqrt(c'')`` alone, the profile likelihood's, would assume
residuals independent from frame to frame and of one variance, whereas smoothing correlates
them over a few frames and the lever arms make their noise differ from frame to frame.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from acs_cli.core import se3
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

__all__ = [
    "MIN_OFFSET_FRAMES",
    "PoseInterpolator",
    "PoseSmoother",
    "TimeOffset",
    "estimate_time_offset",
    "gaussian_profile_cost",
    "profile_cost",
    "shifted_pairs",
    "synchronisation_check",
]

#: Residuals of one calibration: one array ``(m, k)``, or blocks of different kinds.
Residuals = FloatArray | dict[str, FloatArray]
#: A calibration of paired poses ``(m, 4, 4)`` each, returning its residuals.
Fit = Callable[[FloatArray, FloatArray], Residuals]

#: Fewest frames paired at every offset searched.
MIN_OFFSET_FRAMES = 20
#: The grid search and the synchronisation check use at most this many frames (evenly
#: spaced): enough to place the minimum, and a fixed cost per offset tried.
COARSE_FRAMES = 100
#: Largest gap (in median frame intervals) interpolated across.
MAX_GAP_INTERVALS = 1.5
#: Width (standard deviation) of the search's Gaussian weights, in median frame intervals:
#: at 1.5 the smoothing's noise gain varies with the fractional position by about 1e-4 (see
#: :class:`PoseSmoother`).
SMOOTHING_INTERVALS = 1.5
#: The weights are cut at this many widths; a smoothed pose needs this much recording on each
#: side.
KERNEL_CUT = 5.0
#: The standard deviation's stencil step, in median frame intervals.
STENCIL_INTERVALS = 1.0 / 16.0
#: Frames per run in the variance of the cost's slope (longer than the smoothing's
#: correlation of a few frames) ...
SCORE_BLOCK_FRAMES = 10
#: ... and at least this many runs (shorter runs on short recordings).
MIN_SCORE_BLOCKS = 10
#: The refinement's cost where the calibration fails: finite (Brent's parabolic step
#: subtracts costs, and inf - inf is NaN) and above any profile cost (under 400 a residual).
FAILED_COST = 1e100


def _timed_poses(
    times: FloatArray, T_world_cam: FloatArray, name: str = "poses to interpolate"
) -> tuple[FloatArray, FloatArray]:
    """Checked timestamps ``(n,)`` (strictly increasing, ``n >= 4``) and poses ``(n, 4, 4)``
    (``name`` in messages)."""
    t = np.asarray(times, dtype=float)
    T = se3.check_transforms(T_world_cam, name)
    if t.ndim != 1 or t.size != T.shape[0] or t.size < 4:
        raise InputError(
            f"interpolation needs at least 4 timestamped poses, got times {t.shape} and "
            f"{name} {T.shape}"
        )
    if not np.all(np.diff(t) > 0):
        raise InputError(f"interpolation needs strictly increasing timestamps ({name})")
    return t, T


class PoseInterpolator:
    """SE(3) interpolation of a trajectory at arbitrary times.

    Parameters
    ----------
    times : ndarray, shape (n,)
        Strictly increasing sample times (seconds).
    T_world_cam : ndarray, shape (n, 4, 4)
    max_gap : float, optional
        Largest interval between the two samples around a query (seconds); default
        :data:`MAX_GAP_INTERVALS` median intervals.
    """

    def __init__(
        self, times: FloatArray, T_world_cam: FloatArray, max_gap: float | None = None
    ) -> None:
        t, T = _timed_poses(times, T_world_cam)
        self.times = t
        self.interval = float(np.median(np.diff(t)))
        self.max_gap = MAX_GAP_INTERVALS * self.interval if max_gap is None else max_gap
        # lazily: scipy.interpolate and scipy.spatial (with scipy.optimize, which they
        # import) cost ~0.5-1 s a command, and only clock estimation and pairing need them
        from scipy.interpolate import CubicSpline
        from scipy.spatial.transform import Rotation, RotationSpline

        self._rot = RotationSpline(t, Rotation.from_matrix(T[:, :3, :3]))
        self._trans = CubicSpline(t, T[:, :3, 3], axis=0)

    def valid(self, query: FloatArray) -> np.ndarray:
        """Whether each query time ``(k,)`` lies between two samples at most ``max_gap``
        apart (or on a sample)."""
        q = np.asarray(query, dtype=float)
        t = self.times
        inside = (q >= t[0]) & (q <= t[-1])
        hi = np.clip(np.searchsorted(t, q, side="left"), 1, t.size - 1)
        gap = t[hi] - t[hi - 1]
        return np.asarray(inside & (gap <= self.max_gap + 1e-12))

    def __call__(self, query: FloatArray) -> FloatArray:
        """``T_world_cam`` ``(k, 4, 4)`` at the query times (inside the sampled range)."""
        q = np.asarray(query, dtype=float)
        R = self._rot(q).as_matrix()
        return se3.transforms_from_rt(
            R.reshape(-1, 3, 3), np.asarray(self._trans(q)).reshape(-1, 3)
        )


class PoseSmoother:
    """Smoothing of a trajectory at arbitrary times (the time offset search's poses).

    The pose at time ``q`` is a local quadratic regression of the samples' rotation and
    translation blocks on time, with Gaussian weights ``w_j = exp(-(t_j - q)^2 / (2 s^2))``
    (cut at :data:`KERNEL_CUT` ``s``), its rotation block projected onto SO(3). It is linear in
    the samples, ``sum_j l_j(q) T_j``: a polynomial of degree 2 in time is reproduced exactly,
    so the motion is kept to fourth order in ``s`` (a kernel-weighted mean would shrink it to
    second order, and the projection then bends the joint's path by about ``(w s)^2 |o| / 2``
    for an angular rate ``w``: a bias of tenths of a millisecond at 30 Hz). On evenly spaced
    samples of spacing ``d`` the weights' sums equal their integrals up to terms in
    ``exp(-pi^2 s^2 / d^2)``: at ``s = 1.5 d`` white pose noise of variance ``v`` becomes
    ``0.32 v`` at every ``q`` (within 1e-4), whereas a cubic spline's noise gain
    ``sum_j l_j^2`` runs from 1 on a sample to 0.76 half-way.

    Parameters
    ----------
    times : ndarray, shape (n,)
        Strictly increasing sample times (seconds).
    T_world_cam : ndarray, shape (n, 4, 4)
    width : float, optional
        The weights' standard deviation ``s`` (seconds); default
        :data:`SMOOTHING_INTERVALS` median intervals.
    max_gap : float, optional
        Largest interval between samples within the kernel's reach of a query (seconds);
        default :data:`MAX_GAP_INTERVALS` median intervals.
    """

    def __init__(
        self,
        times: FloatArray,
        T_world_cam: FloatArray,
        width: float | None = None,
        max_gap: float | None = None,
    ) -> None:
        t, T = _timed_poses(times, T_world_cam)
        self.times = t
        self.interval = float(np.median(np.diff(t)))
        self.width = SMOOTHING_INTERVALS * self.interval if width is None else width
        self.max_gap = MAX_GAP_INTERVALS * self.interval if max_gap is None else max_gap
        self._T = T
        # gaps[i]: how many intervals among the first i are longer than max_gap
        self._gaps = np.concatenate([[0], np.cumsum(np.diff(t) > self.max_gap + 1e-12)])

    def _window(self, q: FloatArray) -> tuple[np.ndarray, np.ndarray]:
        """First sample within the kernel's reach of each query ``(k,)``, and one past the
        last."""
        reach = KERNEL_CUT * self.width
        lo = np.searchsorted(self.times, q - reach, side="left")
        hi = np.searchsorted(self.times, q + reach, side="right")
        return lo, hi

    def valid(self, query: FloatArray) -> np.ndarray:
        """Whether each query time ``(k,)`` has samples over the kernel's whole reach on both
        sides, without a gap longer than ``max_gap``."""
        q = np.asarray(query, dtype=float)
        lo, hi = self._window(q)
        n = self.times.size
        inside = (lo >= 1) & (hi <= n - 1)
        # the intervals lo - 1 .. hi - 1 span the reach
        a, b = np.clip(lo - 1, 0, n - 1), np.clip(hi, 0, n - 1)
        return np.asarray(inside & (self._gaps[b] == self._gaps[a]))

    def __call__(self, query: FloatArray) -> FloatArray:
        """Smoothed ``T_world_cam`` ``(k, 4, 4)`` at the query times (where :meth:`valid`)."""
        q = np.asarray(query, dtype=float).reshape(-1)
        lo, hi = self._window(q)
        span = int(np.max(hi - lo, initial=1))
        idx = lo[:, None] + np.arange(span)
        inside = idx < hi[:, None]
        idx = np.minimum(idx, self.times.size - 1)
        tau = (self.times[idx] - q[:, None]) / self.width
        w = np.where(inside, np.exp(-0.5 * tau**2), 0.0)
        X = tau[..., None] ** np.arange(3)  # (k, span, 3): 1, tau, tau^2
        S = np.einsum("kj,kja,kjb->kab", w, X, X)
        e0 = np.broadcast_to(np.array([1.0, 0.0, 0.0])[:, None], (q.size, 3, 1))
        coef = np.linalg.solve(S, e0)  # the regression's value at tau = 0 is l @ T
        weights = w * (X @ coef)[..., 0]
        M = np.einsum("kj,kjab->kab", weights, self._T[idx, :3, :])
        R, _ = se3.project_to_rotation(M[:, :, :3])
        return se3.transforms_from_rt(R, M[:, :, 3])


def shifted_pairs(
    times_a: FloatArray,
    interp_b: PoseInterpolator | PoseSmoother,
    offsets: FloatArray,
) -> np.ndarray:
    """The frames of A paired with B at every offset in ``offsets`` (a mask ``(n_a,)``)."""
    ta = np.asarray(times_a, dtype=float)
    ok = np.ones(ta.size, bool)
    for dt in np.asarray(offsets, dtype=float):
        ok &= interp_b.valid(ta + dt)
    return ok


def gaussian_profile_cost(residuals: FloatArray) -> float:
    """Negative log-likelihood (up to a constant) of residuals ``(m, k)`` with one unknown
    isotropic variance: ``(m k / 2) log(RSS / (m k))``."""
    r = np.asarray(residuals, dtype=float)
    rss = float(np.sum(r**2))
    return 0.5 * r.size * float(np.log(max(rss / max(r.size, 1), 1e-300)))


@dataclass(frozen=True)
class TimeOffset:
    """Result of :func:`estimate_time_offset`.

    Attributes
    ----------
    offset_s, std_s : float
        ``dt`` (B's clock minus A's) and its standard deviation, seconds.
    frames : ndarray of bool, shape (n_a,)
        Frames of A paired at every offset searched.
    profile : ndarray, shape (k, 2)
        The grid searched: ``dt`` and the cost.
    at_limit : bool
        The minimum lies at the edge of the searched range (the offset may be larger).
    """

    offset_s: float
    std_s: float
    frames: np.ndarray
    profile: FloatArray
    at_limit: bool


def estimate_time_offset(
    times_a: FloatArray,
    T_a: FloatArray,
    times_b: FloatArray,
    T_b: FloatArray,
    fit: Fit,
    max_offset: float,
) -> TimeOffset:
    """Estimate ``dt`` by minimising the calibration's profile cost over the shift.

    Parameters
    ----------
    times_a, times_b : ndarray, shape (n_a,), (n_b,)
        Timestamps of each camera's poses, seconds, each on its own clock.
    T_a, T_b : ndarray, shape (n_a, 4, 4), (n_b, 4, 4)
        ``T_world_cam`` of each camera.
    fit : (T_a (m, 4, 4), T_b (m, 4, 4)) -> ndarray (m, k) or dict of them
        Calibrates the pair on paired poses and returns its residuals, one row per frame
        (e.g. the joint constraint's, without rejecting outliers, so that every offset sees
        the same frames), or residual blocks of different units (see :func:`profile_cost`);
        it may raise ``DegenerateMotionError`` for an offset far from the truth. During the
        search it is given both cameras' smoothed poses (:class:`PoseSmoother`).
    max_offset : float
        Largest ``|dt|`` searched, seconds.

    Returns
    -------
    TimeOffset
        ``frames`` are those of A whose B-time :class:`PoseInterpolator` covers at every
        offset searched: the caller calibrates on them, raw, paired at ``offset_s``. The
        search uses those of them whose smoothed poses exist at every offset (all but a few
        kernel widths at either end).

    Raises
    ------
    InputError
        Bad timestamps or ``max_offset``.
    DegenerateMotionError
        Too few frames overlap in time over the whole search range.
    """
    if not (np.isfinite(max_offset) and max_offset > 0):
        raise InputError(
            f"the largest offset must be a positive number of seconds, got {max_offset}"
        )
    ta, Ta = _timed_poses(times_a, T_a, "poses of A")
    interp = PoseInterpolator(times_b, T_b)
    step = interp.interval
    k = max(int(np.ceil(max_offset / step)), 2)
    grid = np.linspace(-max_offset, max_offset, 2 * k + 1)
    frames = shifted_pairs(ta, interp, grid)
    # the search: both cameras smoothed alike (one width in seconds, for the slower camera)
    width = SMOOTHING_INTERVALS * max(float(np.median(np.diff(ta))), interp.interval)
    smooth_a = PoseSmoother(ta, Ta, width=width)
    smooth_b = PoseSmoother(times_b, T_b, width=width)
    search = frames & smooth_a.valid(ta) & shifted_pairs(ta, smooth_b, grid)
    if int(search.sum()) < MIN_OFFSET_FRAMES:
        raise DegenerateMotionError(
            f"only {int(search.sum())} frames of A overlap camera B's recording at every "
            f"offset within +-{max_offset:g} s; the time offset needs at least "
            f"{MIN_OFFSET_FRAMES}: record the two cameras together for longer, or search a "
            "smaller --max-offset"
        )
    tf = ta[search]
    Tf = smooth_a(tf)
    coarse = _thinned(tf.size)

    def c(dt: float) -> float:
        return _cost(fit, Tf, smooth_b(tf + dt))

    def c_coarse(dt: float) -> float:
        return _cost(fit, Tf[coarse], smooth_b(tf[coarse] + dt))

    # the grid on at most COARSE_FRAMES frames (the cost's shape is set by the motion, not
    # by the number of frames), the minimum and its curvature on them all
    values = np.array([c_coarse(dt) for dt in grid])
    if not np.any(np.isfinite(values)):
        raise DegenerateMotionError(
            "the calibration fails at every time offset searched; check that the two "
            "trajectories belong to one recording"
        )
    best = int(np.argmin(values))
    lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]

    def c_finite(dt: float) -> float:
        return min(c(dt), FAILED_COST)

    from scipy.optimize import minimize_scalar  # lazily (lsq._least_squares says why)

    res = minimize_scalar(c_finite, bounds=(lo, hi), method="bounded", options={"xatol": 1e-6})
    # the calibration failed at every offset the refinement tried: the grid's minimum
    dt = float(res.x) if res.fun < FAILED_COST else float(grid[best])
    # the residuals at three offsets about dt (inside the range) for the standard deviation
    h = STENCIL_INTERVALS * interp.interval
    mid = float(np.clip(dt, -max_offset + h, max_offset - h))
    stencil = [_residuals(fit, Tf, smooth_b(tf + x)) for x in (mid - h, mid, mid + h)]
    std = _sandwich_std(stencil, h)
    at_limit = best in (0, grid.size - 1)
    return TimeOffset(dt, std, frames, np.column_stack([grid, values]), at_limit)


def _sandwich_std(stencil: list[Residuals | None], h: float) -> float:
    """Standard deviation of the profile cost's minimiser, ``sqrt(Var(c')) / c''``.

    Parameters
    ----------
    stencil : list of 3 residuals (see :func:`estimate_time_offset`'s ``fit``)
        The calibration's residuals at ``dt - h``, ``dt``, ``dt + h``; None where it failed.
    h : float
        The stencil's step, seconds.

    Returns
    -------
    float
        Seconds; infinite where a calibration failed or the curvature is not positive.

    Notes
    -----
    Each block's sum of squares ``S_b`` is nearly quadratic in ``dt`` (its residuals nearly
    linear), so ``c = sum_b (n_b / 2) log(S_b / n_b)`` has the curvature
    ``c'' = sum_b (n_b / 2) (S_b'' / S_b - (S_b' / S_b)^2)``, with ``S_b'`` and ``S_b''`` by
    central differences. (A difference of ``c`` itself would understate it: ``c`` is the log
    of a quadratic, flat beyond the offset at which the signal's residual matches the noise,
    a few milliseconds.) The slope is a sum over frames, ``c' = sum_i u_i`` with
    ``u_i = sum_b r_bi . dr_bi/ddt / (S_b / n_b)`` (``dr/ddt`` with the calibration refitted),
    and its variance is that of the sums of ``u_i`` over runs of :data:`SCORE_BLOCK_FRAMES`
    consecutive frames. Unlike ``1 / sqrt(c'')`` this holds when the residuals are correlated
    in time (the search's smoothing makes them so over a few frames) or their noise varies
    from frame to frame (the lever arms).
    """
    if any(r is None for r in stencil):
        return float("inf")
    lo, r0, hi = (_blocks(r) for r in stencil if r is not None)
    curvature = 0.0
    u = np.zeros(r0[0].shape[0])
    for bl, b, bh in zip(lo, r0, hi, strict=True):
        s_lo, s_0, s_hi = (max(float(np.sum(x**2)), 1e-300) for x in (bl, b, bh))
        d1, d2 = (s_hi - s_lo) / (2.0 * h), (s_hi - 2.0 * s_0 + s_lo) / h**2
        curvature += 0.5 * b.size * (d2 / s_0 - (d1 / s_0) ** 2)
        u += np.sum(b * (bh - bl), axis=1) / (2.0 * h * s_0 / b.size)
    if not curvature > 0:
        return float("inf")
    size = max(1, min(SCORE_BLOCK_FRAMES, u.size // MIN_SCORE_BLOCKS))
    sums = np.add.reduceat(u, np.arange(0, u.size, size))
    var = float(np.sum((sums - sums.mean()) ** 2)) * sums.size / max(sums.size - 1, 1)
    return float(np.sqrt(var) / curvature)


def _blocks(residuals: Residuals) -> list[FloatArray]:
    """Residual blocks ``(m, k_b)`` each (one row per frame) as a list."""
    raw = residuals.values() if isinstance(residuals, dict) else [residuals]
    out = [np.asarray(r, dtype=float).reshape(np.shape(r)[0], -1) for r in raw]
    if len({b.shape[0] for b in out}) > 1:
        raise ValueError("residual blocks must have one row per frame")
    return out


def _thinned(n: int) -> np.ndarray:
    """Indices of at most :data:`COARSE_FRAMES` of ``n`` frames, evenly spaced."""
    return np.unique(np.round(np.linspace(0, n - 1, min(n, COARSE_FRAMES))).astype(int))


def _residuals(fit: Fit, Ta: FloatArray, Tb: FloatArray) -> Residuals | None:
    """The residuals of one pairing (None where the calibration fails)."""
    try:
        return fit(Ta, Tb)
    except DegenerateMotionError:
        return None


def _cost(fit: Fit, Ta: FloatArray, Tb: FloatArray) -> float:
    """The profile cost of one pairing (infinite where the calibration fails)."""
    r = _residuals(fit, Ta, Tb)
    return float("inf") if r is None else profile_cost(r)


def profile_cost(residuals: Residuals) -> float:
    """:func:`gaussian_profile_cost` of residuals ``(m, k)``, or the sum over blocks of
    residuals of different kinds (each with its own variance: metres, radians)."""
    if isinstance(residuals, dict):
        return float(sum(gaussian_profile_cost(r) for r in residuals.values()))
    return gaussian_profile_cost(residuals)


#: The synchronisation check flags a shift that lowers the cost by more than this (a
#: likelihood ratio of e^10: far beyond chance) ...
SYNC_CHECK_COST = 10.0
#: ... and the residuals' RMS by more than this fraction.
SYNC_CHECK_RESIDUAL = 0.1


def synchronisation_check(
    times_a: FloatArray,
    T_a: FloatArray,
    times_b: FloatArray,
    T_b: FloatArray,
    fit: Fit,
    steps: tuple[float, ...] = (-1.0, -0.5, 0.5, 1.0),
) -> tuple[float, float] | None:
    """Whether shifting B's clock by half or one frame interval fits clearly better.

    Compares the pairing at ``dt = 0`` with ``dt = steps x interval`` on (at most
    :data:`COARSE_FRAMES` of) the frames valid at all of them (see
    :func:`estimate_time_offset` for ``fit``).

    Returns
    -------
    (dt, ratio) or None
        The best shift (seconds) and its residual RMS relative to ``dt = 0``, when it lowers
        the cost by more than :data:`SYNC_CHECK_COST` and the RMS by more than
        :data:`SYNC_CHECK_RESIDUAL`; None otherwise, or when it cannot be checked (too few
        frames, or snapshots rather than a video: A turning more than
        :data:`SYNC_CHECK_MAX_STEP_DEG` between frames).
    """
    try:
        interp = PoseInterpolator(times_b, T_b)
    except InputError:
        return None
    Ta = np.asarray(T_a, dtype=float)
    if not _video_like(Ta):
        return None
    ta = np.asarray(times_a, dtype=float)
    shifts = interp.interval * np.array([0.0, *steps])
    frames = np.flatnonzero(shifted_pairs(ta, interp, shifts))
    if frames.size < MIN_OFFSET_FRAMES:
        return None
    frames = frames[_thinned(frames.size)]
    res: list[Residuals | None] = []
    for dt in shifts:
        try:
            res.append(fit(Ta[frames], interp(ta[frames] + dt)))
        except DegenerateMotionError:
            res.append(None)
    r0 = res[0]
    if r0 is None:
        return None
    base = profile_cost(r0)
    best: tuple[float, float] | None = None
    best_cost = base - SYNC_CHECK_COST
    for dt, r in zip(shifts[1:], res[1:], strict=True):
        if r is None:
            continue
        cost = profile_cost(r)
        ratio = _rms_ratio(r, r0)
        if cost < best_cost and ratio < 1.0 - SYNC_CHECK_RESIDUAL:
            best, best_cost = (float(dt), ratio), cost
    return best


#: The check needs motion sampled finely enough for a shift by a frame to pair nearly the
#: same poses: camera A turning less than this between frames (median, degrees).
SYNC_CHECK_MAX_STEP_DEG = 10.0


def _video_like(T: FloatArray) -> bool:
    """Whether consecutive poses are close (a video, not independent snapshots)."""
    if T.shape[0] < 3:
        return False
    R = T[:, :3, :3]
    steps = se3.rotation_angle_deg(np.matmul(np.swapaxes(R[:-1], 1, 2), R[1:]))
    return bool(np.median(steps) < SYNC_CHECK_MAX_STEP_DEG)


def _rms_ratio(r: Residuals, r0: Residuals) -> float:
    """RMS of ``r`` over that of ``r0`` (of their first block: the position residuals)."""
    a = next(iter(r.values())) if isinstance(r, dict) else r
    b = next(iter(r0.values())) if isinstance(r0, dict) else r0
    return float(np.sqrt(np.mean(a**2)) / max(float(np.sqrt(np.mean(b**2))), 1e-300))
