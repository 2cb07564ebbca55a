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
compare. A grid of steps of half a frame interval is refined by a bounded Brent search around its
best point; the standard deviation is ``1 / sqrt(c'')`` at the minimum (the profile
likelihood's curvature, by central differences).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation, RotationSpline

from acs_cli.core import se3
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError, InputError

__all__ = [
    "MIN_OFFSET_FRAMES",
    "PoseInterpolator",
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
        t = np.asarray(times, dtype=float)
        T = se3.check_transforms(T_world_cam, "poses to interpolate")
        if t.ndim != 1 or t.size != T.shape[0] or t.size < 4:
            raise InputError(
                f"interpolation needs at least 4 timestamped poses, got times {t.shape} and "
                f"poses {T.shape}"
            )
        if not np.all(np.diff(t) > 0):
            raise InputError("interpolation needs strictly increasing timestamps")
        self.times = t
        self.interval = float(np.median(np.diff(t)))
        self.max_gap = MAX_GAP_INTERVALS * self.interval if max_gap is None else max_gap
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


def shifted_pairs(
    times_a: FloatArray,
    interp_b: PoseInterpolator,
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
        Calibrates the pair on paired poses and returns its residuals (e.g. the joint
        constraint's, without rejecting outliers, so that every offset sees the same
        frames), or residual blocks of different units (see :func:`profile_cost`); it may
        raise ``DegenerateMotionError`` for an offset far from the truth.
    max_offset : float
        Largest ``|dt|`` searched, seconds.

    Returns
    -------
    TimeOffset

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
    Ta = se3.check_transforms(T_a, "poses of A")
    ta = np.asarray(times_a, dtype=float)
    if ta.shape != (Ta.shape[0],):
        raise InputError(f"{ta.size} timestamps for {Ta.shape[0]} poses of A")
    interp = PoseInterpolator(times_b, T_b)
    step = 0.5 * interp.interval
    k = max(int(np.ceil(max_offset / step)), 2)
    grid = np.linspace(-max_offset, max_offset, 2 * k + 1)
    frames = shifted_pairs(ta, interp, grid)
    if int(frames.sum()) < MIN_OFFSET_FRAMES:
        raise DegenerateMotionError(
            f"only {int(frames.sum())} frames of A overlap camera B's recording at every "
            f"offset within +-{max_offset:g} s; the time offset needs at least "
            f"{MIN_OFFSET_FRAMES}: record the two cameras together for longer, or search a "
            "smaller --max-offset"
        )
    Tf, tf = Ta[frames], ta[frames]
    coarse = _thinned(tf.size)

    def c(dt: float) -> float:
        return _cost(fit, Tf, interp(tf + dt))

    def c_coarse(dt: float) -> float:
        return _cost(fit, Tf[coarse], interp(tf[coarse] + dt))

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
    res = minimize_scalar(c, bounds=(lo, hi), method="bounded", options={"xatol": 1e-6})
    dt = float(res.x)
    h = 0.25 * step
    lo_c, hi_c = c(max(dt - h, -max_offset)), c(min(dt + h, max_offset))
    curvature = (lo_c - 2.0 * c(dt) + hi_c) / h**2
    std = float(1.0 / np.sqrt(curvature)) if curvature > 0 else float("inf")
    at_limit = best in (0, grid.size - 1)
    return TimeOffset(dt, std, frames, np.column_stack([grid, values]), at_limit)


def _thinned(n: int) -> np.ndarray:
    """Indices of at most :data:`COARSE_FRAMES` of ``n`` frames, evenly spaced."""
    return np.unique(np.round(np.linspace(0, n - 1, min(n, COARSE_FRAMES))).astype(int))


def _cost(fit: Fit, Ta: FloatArray, Tb: FloatArray) -> float:
    """The profile cost of one pairing (infinite where the calibration fails)."""
    try:
        return profile_cost(fit(Ta, Tb))
    except DegenerateMotionError:
        return float("inf")


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
