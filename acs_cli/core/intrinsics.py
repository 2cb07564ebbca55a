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

Degenerate distortion (:func:`degenerate_distortion`): a fit can reach a low RMS with
coefficients the views do not determine (``rational`` on a nearly pinhole lens gave
``k1 = 19, k2 = -593, k3 = 3274``: numerator and denominator cancel). From the covariance of
the intrinsics (:func:`intrinsics_covariance`, the Jacobian of the reprojection residuals
with every view's pose marginalised out; OpenCV gives only standard deviations, and none for
the fisheye model), a distortion is degenerate when a coefficient larger than
:data:`HUGE_COEFFICIENT` has a standard deviation larger than itself, or when two such
coefficients are correlated beyond :data:`DEGENERATE_CORRELATION` (they trade off against
each other, as a rational model's numerator and denominator do).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from acs_cli.core import se3
from acs_cli.core.camera_models import camera_model
from acs_cli.errors import DegenerateMotionError

__all__ = [
    "DEGENERATE_CORRELATION",
    "DISTORTION_NAMES",
    "HUGE_COEFFICIENT",
    "MIN_VIEWS",
    "MODELS",
    "CalibrationResult",
    "board_points",
    "calibrate",
    "calibrate_robust",
    "degenerate_distortion",
    "distinct_poses",
    "honest_std",
    "intrinsics_covariance",
    "outlier_views",
    "std_from_covariance",
]

MODELS = ("pinhole", "rational", "fisheye")
#: Names of the distortion coefficients of each model, in OpenCV's order.
DISTORTION_NAMES = {
    "pinhole": ("k1", "k2", "p1", "p2", "k3"),
    "rational": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
    "fisheye": ("k1", "k2", "k3", "k4"),
}
#: Fewest board views a calibration accepts: distinct board poses (:func:`distinct_poses`).
MIN_VIEWS = 3
#: Two views show the board in the same pose when their homographies place its outline
#: within this fraction of its image diagonal (RMS over the outline's corners and centre):
#: 0.5% is about 2.5 degrees of tilt about the board's centre, or 1% of its distance.
DISTINCT_FRACTION = 0.005
#: ... or within this many pixels (a small board's floor: corner noise of 0.1-0.5 px moves
#: the outline of a homography fitted on many corners by 0.1-0.4 px).
DISTINCT_MIN_PX = 0.5
#: The coefficients :func:`calibrate` holds for each model (``CALIB_FIX_K3`` for pinhole).
CALIBRATION_HELD = {"pinhole": ("k3",), "rational": (), "fisheye": ()}
#: A distortion coefficient above this magnitude (unitless) whose standard deviation exceeds
#: it is not determined by the views (real lenses need |k| well below 1 in the pinhole model;
#: larger values come from terms that cancel).
HUGE_COEFFICIENT = 1.0
#: Two distortion coefficients above :data:`HUGE_COEFFICIENT` correlated beyond this
#: (absolute value) are not separated by the views.
DEGENERATE_CORRELATION = 0.999

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
    distinct : int
        Distinct board poses among the views used (:func:`distinct_poses`).
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
    distinct: int = 0


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


def _outline(object_points: Sequence[NDArray[np.floating]]) -> FloatArray | None:
    """The board's bounding rectangle's corners and centre, ``(5, 2)`` in the board plane,
    or None when a view's points are not on the plane ``z = 0``."""
    pts = [np.asarray(p, dtype=float).reshape(-1, 3) for p in object_points]
    allp = np.concatenate(pts)
    span = float(np.ptp(allp[:, :2], axis=0).max())
    if span <= 0.0 or np.abs(allp[:, 2]).max() > 1e-9 * span:
        return None
    (x0, y0), (x1, y1) = allp[:, :2].min(axis=0), allp[:, :2].max(axis=0)
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [(x0 + x1) / 2, (y0 + y1) / 2]])


def distinct_poses(
    object_points: Sequence[NDArray[np.floating]],
    image_points: Sequence[NDArray[np.floating]],
) -> NDArray[np.intp]:
    """Group the views that show the board in the same pose (frames of a tripod video).

    Each view's board-to-image homography maps the board's outline (bounding rectangle and
    centre) into the image; a view joins the first earlier group whose first view places the
    outline within :data:`DISTINCT_FRACTION` of the outline's image diagonal (or
    :data:`DISTINCT_MIN_PX`), RMS. Homographies need no intrinsics, so duplicates are found
    before the calibration (which they would make degenerate). Views of a non-planar target,
    or with too few points for a homography, each count as distinct.

    Parameters
    ----------
    object_points : sequence of ndarray, shape (m_i, 3)
        Board points of each view (board frame, ``z = 0``).
    image_points : sequence of ndarray, shape (m_i, 2)
        Their detections, pixels.

    Returns
    -------
    ndarray of int, shape (n_views,)
        A group label per view, ``0 .. k-1`` in order of first appearance (``k`` the
        number of distinct poses).
    """
    n = len(image_points)
    labels = np.arange(n)
    outline = _outline(object_points) if n else None
    if outline is None:
        return labels
    mapped: list[FloatArray | None] = []
    for obj, img in zip(object_points, image_points, strict=True):
        src = np.asarray(obj, dtype=np.float64).reshape(-1, 3)[:, :2]
        dst = np.asarray(img, dtype=np.float64).reshape(-1, 2)
        H = None if src.shape[0] < 4 else cv2.findHomography(src, dst, 0)[0]
        if H is None or not np.all(np.isfinite(H)):
            mapped.append(None)
            continue
        h = np.column_stack([outline, np.ones(5)]) @ np.asarray(H, dtype=np.float64).T
        mapped.append(h[:, :2] / h[:, 2:] if np.all(np.abs(h[:, 2]) > 1e-12) else None)
    groups = 0
    firsts: list[FloatArray] = []  # the outline of each group's first view
    first_label: list[int] = []
    for i, q in enumerate(mapped):
        if q is not None and firsts:
            diag = max(np.linalg.norm(q[2] - q[0]), np.linalg.norm(q[3] - q[1]))
            tol = max(DISTINCT_FRACTION * float(diag), DISTINCT_MIN_PX)
            rms = np.sqrt(np.mean(np.sum((np.asarray(firsts) - q) ** 2, axis=2), axis=1))
            near = np.flatnonzero(rms < tol)
            if near.size:
                labels[i] = first_label[int(near[0])]
                continue
        labels[i] = groups
        if q is not None:
            firsts.append(q)
            first_label.append(groups)
        groups += 1
    return labels


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
        Fewer than :data:`MIN_VIEWS` views or distinct board poses (:func:`distinct_poses`),
        or OpenCV cannot calibrate from them.
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
    distinct = int(distinct_poses(object_points, image_points).max()) + 1
    if distinct < MIN_VIEWS:
        raise DegenerateMotionError(
            f"{n} views of the board, but they show it from only {distinct} distinct "
            f"pose{'s' if distinct > 1 else ''} (a tripod video?): calibration needs at least "
            f"{MIN_VIEWS}; move the board or the camera between images: different distances "
            "and tilts",
            details={"views": n, "distinct_poses": distinct},
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
            # a step under 1e-9 of the parameters ends it: the intrinsics agree with a 1e-12
            # stop to 1e-8 px (rwhe_kuka1, OpenCV's stereo photographs), in half the steps
            crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-9)
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
        distinct=distinct,
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
    keep = np.setdiff1d(np.arange(len(image_points)), bad).tolist()
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
        distinct=second.distinct,
    )


def intrinsics_covariance(
    result: CalibrationResult,
    object_points: Sequence[NDArray[np.floating]],
    image_points: Sequence[NDArray[np.floating]],
) -> FloatArray:
    """Covariance of a calibration's intrinsics, from the Jacobian of its residuals.

    Every view's pose (6 unknowns) is marginalised out (Schur complement of the
    information), the corner noise is the fit's (residual sum of squares over the degrees
    of freedom), and the intrinsics the calibration held (``k3`` of the pinhole model,
    ``CALIB_FIX_K3``) have zero rows and columns.

    Parameters
    ----------
    result : CalibrationResult
        From :func:`calibrate` or :func:`calibrate_robust` on the views below.
    object_points, image_points : sequence of ndarray, shape (m_i, 3) and (m_i, 2)
        The views given to the calibration (metres, pixels); ``result.used`` picks the
        ones it used, in the order of its poses.

    Returns
    -------
    ndarray, shape (p, p)
        Of the intrinsic vector ``fx fy cx cy`` (px) and the model's distortion
        (:attr:`acs_cli.core.camera_models.CameraModel.names`).
    """
    cam = camera_model(result.model)
    intr = cam.vector(result.camera_matrix, result.distortion)
    used = list(result.used) if result.used else list(range(len(image_points)))
    if len(used) != result.rvecs.shape[0]:
        raise ValueError(f"{len(used)} views used but {result.rvecs.shape[0]} poses")
    X = [np.asarray(object_points[i], dtype=float).reshape(-1, 3) for i in used]
    counts = np.array([x.shape[0] for x in X])
    if np.any(counts == 0):
        raise ValueError("a view the calibration used has no points")
    view = np.repeat(np.arange(len(used)), counts)
    obj = np.concatenate(X)
    px = np.concatenate([np.asarray(image_points[i], dtype=float).reshape(-1, 2) for i in used])
    R = se3.matrix_from_rotvec(result.rvecs)[view]
    Rx = np.einsum("kij,kj->ki", R, obj)
    x_cam = Rx + result.tvecs[view]
    res = cam.project(x_cam, intr) - px
    free = cam.free(CALIBRATION_HELD[result.model])
    Di, Dp = cam.jacobians(x_cam, intr)
    Di = Di[:, :, free]
    # pose perturbation Exp(d) R, t + e: d x_cam = -[R X]x d + e
    Jp = np.concatenate([-np.matmul(Dp, se3.skew(Rx)), Dp], axis=2)  # (k, 2, 6)
    n_views, p = len(used), len(free)
    H_ii = Di.reshape(-1, p).T @ Di.reshape(-1, p)
    # per view: sums over its points (consecutive, none empty) of J_i^T J_p and J_p^T J_p
    starts = np.cumsum(counts) - counts
    H_ip = np.add.reduceat(np.matmul(np.swapaxes(Di, 1, 2), Jp), starts, axis=0)
    H_pp = np.add.reduceat(np.matmul(np.swapaxes(Jp, 1, 2), Jp), starts, axis=0)
    S = H_ii - np.einsum("vij,vjk->ik", H_ip, np.linalg.solve(H_pp, np.swapaxes(H_ip, 1, 2)))
    dof = max(res.size - p - 6 * n_views, 1)
    sigma2 = float(np.sum(res**2) / dof)
    d = 1.0 / np.sqrt(np.maximum(np.diag(S), 1e-300))  # unit diagonal: far better conditioned
    Sn = S * np.outer(d, d)
    try:
        inv = np.linalg.inv(Sn)
    except np.linalg.LinAlgError:
        inv = np.linalg.pinv(Sn, hermitian=True)
    cov = np.zeros((cam.size, cam.size))
    cov[np.ix_(free, free)] = sigma2 * 0.5 * (inv + inv.T) * np.outer(d, d)
    return cov


def std_from_covariance(covariance: NDArray[np.floating]) -> dict[str, object]:
    """One-sigma standard deviations of a calibration from its intrinsics' covariance.

    Parameters
    ----------
    covariance : ndarray, shape (4 + m, 4 + m)
        Of ``fx fy cx cy`` (px) and ``m`` distortion coefficients, as
        :func:`intrinsics_covariance` returns it.

    Returns
    -------
    dict
        ``fx``, ``fy``, ``cx``, ``cy`` (px) and ``distortion`` (list, unitless), the layout
        of :attr:`CalibrationResult.std_intrinsics`.
    """
    s = np.sqrt(np.maximum(np.diag(np.asarray(covariance, dtype=float)), 0.0))
    return {
        "fx": float(s[0]),
        "fy": float(s[1]),
        "cx": float(s[2]),
        "cy": float(s[3]),
        "distortion": [float(v) for v in s[4:]],
    }


def honest_std(result: CalibrationResult, covariance: NDArray[np.floating]) -> dict[str, object]:
    """The standard deviations to report: per parameter the larger of OpenCV's and the
    covariance's (:func:`std_from_covariance`), times ``sqrt(views / distinct poses)``.

    OpenCV's come out far too small when the views are nearly degenerate (one pose seen 20
    times: 0.2 px on an fx 150 px off); and repeated views of one pose share their corner
    errors (same blur, same light), so they do not average them down as independent views
    would: a pose seen ``r`` times counts once.

    Parameters
    ----------
    result : CalibrationResult
        Its ``std_intrinsics`` (empty for fisheye), ``used`` and ``distinct``.
    covariance : ndarray, shape (4 + m, 4 + m)
        :func:`intrinsics_covariance` of it.

    Returns
    -------
    dict
        The layout of :attr:`CalibrationResult.std_intrinsics`.
    """
    ours = std_from_covariance(covariance)
    theirs = result.std_intrinsics
    views = len(result.used) or result.rvecs.shape[0]
    inflate = float(np.sqrt(views / result.distinct)) if result.distinct else 1.0

    def pick(key: str) -> Any:
        a, b = ours[key], theirs.get(key, ours[key])
        if isinstance(a, list):
            b = list(b) if isinstance(b, list) and len(b) == len(a) else a
            return [inflate * max(float(x), float(y)) for x, y in zip(a, b, strict=True)]
        return inflate * max(float(a), float(b))  # type: ignore[arg-type]

    return {key: pick(key) for key in ("fx", "fy", "cx", "cy", "distortion")}


def degenerate_distortion(
    model: str, distortion: NDArray[np.floating], covariance: NDArray[np.floating]
) -> str | None:
    """Why a fitted distortion is not determined by its data, or None when it is.

    Parameters
    ----------
    model : {"pinhole", "rational", "fisheye"}
    distortion : ndarray, shape (m,)
        The coefficients, named by ``DISTORTION_NAMES[model]`` (unitless).
    covariance : ndarray, shape (m, m)
        Their covariance (zero rows and columns for coefficients held fixed).

    Returns
    -------
    str or None
        A warning naming each coefficient larger than :data:`HUGE_COEFFICIENT` whose
        standard deviation exceeds it, and each pair of such large coefficients correlated
        beyond :data:`DEGENERATE_CORRELATION` (the first four findings, then their count).
    """
    names = DISTORTION_NAMES[model]
    v = np.asarray(distortion, dtype=float).ravel()
    C = np.asarray(covariance, dtype=float)
    if v.shape != (len(names),) or C.shape != (v.size, v.size):
        raise ValueError(
            f"{model}: {len(names)} coefficients and their covariance expected, got "
            f"{v.shape} and {C.shape}"
        )
    std = np.sqrt(np.clip(np.diag(C), 0.0, None))
    problems = [
        f"{names[i]} = {v[i]:.4g} +- {std[i]:.2g}"
        for i in np.flatnonzero((np.abs(v) > HUGE_COEFFICIENT) & (std > np.abs(v)))
    ]
    large = np.flatnonzero((std > 0) & (np.abs(v) > HUGE_COEFFICIENT))
    corr = C[np.ix_(large, large)] / np.outer(std[large], std[large])
    i, j = np.nonzero(np.triu(np.abs(corr) > DEGENERATE_CORRELATION, k=1))
    problems += [
        f"{names[large[a]]} = {v[large[a]]:.4g} and {names[large[b]]} = {v[large[b]]:.4g} "
        f"correlated at {corr[a, b]:+.4f}"
        for a, b in zip(i, j, strict=True)
    ]
    if not problems:
        return None
    more = f"; and {len(problems) - 4} more" if len(problems) > 4 else ""
    return (
        f"the {model} distortion is degenerate ({'; '.join(problems[:4])}{more}): the views do not "
        "determine these coefficients, so the model may extrapolate wildly beyond the corners "
        "seen; use a model with fewer coefficients (pinhole), or views whose corners reach the "
        "image's edges and corners"
    )
