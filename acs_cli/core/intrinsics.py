"""Camera intrinsics from checkerboard views: OpenCV calibration with outlier views dropped.

Models:

- ``pinhole``: pinhole + radial-tangential distortion ``[k1, k2, p1, p2, k3]``
  (``cv2.calibrateCameraExtended``) with ``k3`` fixed at 0 (``CALIB_FIX_K3``, the four
  coefficients of Kalibr's ``radtan``): with a board that covers the middle of the image,
  ``k2`` and ``k3`` trade off against each other and a free ``k3`` lands far off (seen on
  rendered sequences: 0.56 for a true 0.005), which biases everything downstream. Use
  ``rational`` for lenses that need more;
- ``rational``: pinhole + the rational model ``[k1, k2, p1, p2, k3, k4, k5, k6]``
  (``CALIB_RATIONAL_MODEL``);
- ``fisheye``: the equidistant (Kannala-Brandt) model ``[k1, k2, k3, k4]``
  (``cv2.fisheye.calibrate``).

Outlier rule (:func:`outlier_views`): a view is dropped when its reprojection RMS exceeds
both ``median + 3 * 1.4826 * MAD`` and ``2 * median`` of all views' RMS, and the camera is
calibrated again without it (one round). Pixels are OpenCV's (top-left pixel centre at 0).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from acs_cli.errors import DegenerateMotionError

__all__ = [
    "DISTORTION_NAMES",
    "MIN_VIEWS",
    "MODELS",
    "CalibrationResult",
    "board_points",
    "calibrate",
    "calibrate_robust",
    "outlier_views",
]

MODELS = ("pinhole", "rational", "fisheye")
#: Names of the distortion coefficients of each model, in OpenCV's order.
DISTORTION_NAMES = {
    "pinhole": ("k1", "k2", "p1", "p2", "k3"),
    "rational": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
    "fisheye": ("k1", "k2", "k3", "k4"),
}
#: Fewest board views a calibration accepts.
MIN_VIEWS = 3

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CalibrationResult:
    """An intrinsic calibration.

    Attributes
    ----------
    model : str
        One of :data:`MODELS`.
    camera_matrix : ndarray, shape (3, 3)
        ``K`` in pixels.
    distortion : ndarray, shape (m,)
        Coefficients named by ``DISTORTION_NAMES[model]``.
    image_size : tuple of int
        ``(width, height)`` in pixels.
    rms_px : float
        Overall reprojection RMS over all corners of all views, pixels.
    per_view_rms : ndarray, shape (n_views,)
        Reprojection RMS of each view used, pixels.
    std_intrinsics : dict
        One-sigma standard deviations: ``fx``, ``fy``, ``cx``, ``cy`` (pixels) and
        ``distortion`` (list, unitless), or an empty dict when OpenCV gives none (fisheye).
    rvecs, tvecs : ndarray, shape (n_views, 3)
        ``T_cam_board`` of each view (Rodrigues vector, radians; translation in the board's
        length unit).
    dropped : tuple of int
        Indices (into the views given to :func:`calibrate_robust`) dropped as outliers.
    used : tuple of int
        Indices of the views this calibration used.
    first_pass_per_view_rms : ndarray, shape (n_views_given,)
        Per-view RMS of the first calibration, before any view was dropped.
    """

    model: str
    camera_matrix: FloatArray
    distortion: FloatArray
    image_size: tuple[int, int]
    rms_px: float
    per_view_rms: FloatArray
    std_intrinsics: dict[str, object]
    rvecs: FloatArray
    tvecs: FloatArray
    dropped: tuple[int, ...] = ()
    used: tuple[int, ...] = ()
    first_pass_per_view_rms: FloatArray = field(default_factory=lambda: np.zeros(0))


def board_points(cols: int, rows: int, square: float) -> FloatArray:
    """The board's inner corners in the board frame.

    Parameters
    ----------
    cols, rows : int
        Inner corners along x and y.
    square : float
        Square side length (metres, or the caller's unit).

    Returns
    -------
    ndarray, shape (cols * rows, 3)
        Row by row: ``(i * square, j * square, 0)`` for row ``j``, column ``i``; the origin
        is the first inner corner, z into the board.
    """
    j, i = np.mgrid[0:rows, 0:cols]
    pts = np.zeros((rows * cols, 3))
    pts[:, 0] = i.ravel() * square
    pts[:, 1] = j.ravel() * square
    return pts


def outlier_views(per_view_rms: NDArray[np.floating]) -> NDArray[np.intp]:
    """Indices of views whose RMS is far above the rest.

    A view is an outlier when its RMS exceeds both ``median + 3 * 1.4826 * MAD`` and
    ``2 * median`` (so a tight set of good views does not shed views over tiny
    differences). With fewer than 4 views nothing is dropped.

    Parameters
    ----------
    per_view_rms : ndarray, shape (n,)
        Reprojection RMS per view, pixels.

    Returns
    -------
    ndarray of int
        Sorted indices of the outlier views.
    """
    e = np.asarray(per_view_rms, dtype=float).ravel()
    if e.size < 4:
        return np.zeros(0, dtype=np.intp)
    med = float(np.median(e))
    mad = float(np.median(np.abs(e - med)))
    limit = max(med + 3.0 * 1.4826 * mad, 2.0 * med)
    return np.flatnonzero(e > limit)


def _fisheye_calibrate(
    obj: Sequence[FloatArray], img: Sequence[FloatArray], size: tuple[int, int]
) -> tuple[float, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, dict[str, object]]:
    o = [np.asarray(p, np.float64).reshape(1, -1, 3) for p in obj]
    q = [np.asarray(p, np.float64).reshape(1, -1, 2) for p in img]
    flags = cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-9)
    _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(
        o, q, size, np.zeros((3, 3)), np.zeros((4, 1)), flags=flags, criteria=crit
    )
    errs = []
    sq = 0.0
    count = 0
    for oi, qi, rv, tv in zip(o, q, rvecs, tvecs, strict=True):
        proj, _ = cv2.fisheye.projectPoints(oi, rv, tv, K, D)
        d2 = np.sum((proj.reshape(-1, 2) - qi.reshape(-1, 2)) ** 2, axis=1)
        errs.append(np.sqrt(d2.mean()))
        sq += float(d2.sum())
        count += d2.size
    rms = float(np.sqrt(sq / max(count, 1)))
    rv = np.asarray(rvecs, np.float64).reshape(-1, 3)
    tv = np.asarray(tvecs, np.float64).reshape(-1, 3)
    Kf = np.asarray(K, np.float64)
    Df = np.asarray(D, np.float64).ravel()
    return rms, Kf, Df, rv, tv, np.array(errs, dtype=np.float64), {}


def calibrate(
    object_points: Sequence[NDArray[np.floating]],
    image_points: Sequence[NDArray[np.floating]],
    image_size: tuple[int, int],
    model: str = "pinhole",
) -> CalibrationResult:
    """Calibrate a camera from board views (one pass, no outlier rejection).

    Parameters
    ----------
    object_points : sequence of ndarray, shape (m, 3)
        Board corners in the board frame, one array per view (metres).
    image_points : sequence of ndarray, shape (m, 2)
        Their detections, pixels.
    image_size : tuple of int
        ``(width, height)``, pixels.
    model : {"pinhole", "rational", "fisheye"}

    Returns
    -------
    CalibrationResult

    Raises
    ------
    ValueError
        An unknown model or mismatched inputs (a programming error).
    DegenerateMotionError
        Fewer than :data:`MIN_VIEWS` views, or OpenCV cannot calibrate from them.
    """
    if model not in MODELS:
        raise ValueError(f"unknown camera model {model!r}")
    if len(object_points) != len(image_points):
        raise ValueError("object_points and image_points differ in length")
    n = len(image_points)
    if n < MIN_VIEWS:
        raise DegenerateMotionError(
            f"only {n} view(s) of the board: calibration needs at least {MIN_VIEWS}, "
            "taken at different distances and tilts"
        )
    w, h = int(image_size[0]), int(image_size[1])
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)  # OpenCV's parallel reductions make results differ in the last bits
    try:
        if model == "fisheye":
            rms, K, dist, rv, tv, errs, std = _fisheye_calibrate(
                [np.asarray(p, float) for p in object_points],
                [np.asarray(p, float) for p in image_points],
                (w, h),
            )
        else:
            o = [np.asarray(p, np.float32).reshape(-1, 1, 3) for p in object_points]
            q = [np.asarray(p, np.float32).reshape(-1, 1, 2) for p in image_points]
            flags = cv2.CALIB_RATIONAL_MODEL if model == "rational" else cv2.CALIB_FIX_K3
            crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
            res = cv2.calibrateCameraExtended(
                o, q, (w, h), np.zeros((3, 3)), np.zeros((8, 1)), flags=flags, criteria=crit
            )
            rms, K_raw, D, rvecs, tvecs, std_in, _, per_view = res
            m = len(DISTORTION_NAMES[model])
            dist = np.asarray(D, float).ravel()[:m]
            s = np.asarray(std_in, float).ravel()
            std = {
                "fx": float(s[0]),
                "fy": float(s[1]),
                "cx": float(s[2]),
                "cy": float(s[3]),
                "distortion": [float(v) for v in s[4 : 4 + m]],
            }
            K = np.asarray(K_raw, np.float64)
            rv = np.asarray(rvecs, float).reshape(-1, 3)
            tv = np.asarray(tvecs, float).reshape(-1, 3)
            errs = np.asarray(per_view, float).ravel()
    except cv2.error as exc:
        raise DegenerateMotionError(
            f"OpenCV could not calibrate from {n} views ({str(exc).strip().splitlines()[-1]}); "
            "record more views at different tilts"
        ) from exc
    finally:
        cv2.setNumThreads(threads)
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(dist)) and np.isfinite(rms)):
        raise DegenerateMotionError(
            f"calibration from {n} views did not converge; record more views at different tilts"
        )
    return CalibrationResult(
        model=model,
        camera_matrix=K,
        distortion=dist,
        image_size=(w, h),
        rms_px=float(rms),
        per_view_rms=errs,
        std_intrinsics=std,
        rvecs=rv,
        tvecs=tv,
        used=tuple(range(n)),
        first_pass_per_view_rms=errs,
    )


def calibrate_robust(
    object_points: Sequence[NDArray[np.floating]],
    image_points: Sequence[NDArray[np.floating]],
    image_size: tuple[int, int],
    model: str = "pinhole",
) -> CalibrationResult:
    """Calibrate, drop outlier views (:func:`outlier_views`) and calibrate again.

    Parameters and exceptions are those of :func:`calibrate`. The result's ``used`` and
    ``dropped`` index the given views; ``per_view_rms`` follows ``used``.
    """
    first = calibrate(object_points, image_points, image_size, model)
    bad = outlier_views(first.per_view_rms)
    if bad.size == 0 or len(image_points) - bad.size < MIN_VIEWS:
        return first
    keep = [i for i in range(len(image_points)) if i not in set(bad.tolist())]
    second = calibrate(
        [object_points[i] for i in keep], [image_points[i] for i in keep], image_size, model
    )
    return CalibrationResult(
        model=second.model,
        camera_matrix=second.camera_matrix,
        distortion=second.distortion,
        image_size=second.image_size,
        rms_px=second.rms_px,
        per_view_rms=second.per_view_rms,
        std_intrinsics=second.std_intrinsics,
        rvecs=second.rvecs,
        tvecs=second.tvecs,
        dropped=tuple(int(i) for i in bad),
        used=tuple(keep),
        first_pass_per_view_rms=first.per_view_rms,
    )
