"""Checkerboard corner detection: a fast coarse search, then an accurate sub-pixel refinement.

The detector (:func:`detect_checkerboard`) works in three steps:

1. **Coarse search** on a copy of the image downscaled to at most :data:`COARSE_WIDTH`
   pixels wide, with OpenCV's classic ``findChessboardCorners`` (adaptive threshold;
   no image normalisation, which costs time and gained nothing). Before it,
   ``cv2.checkChessboard`` (the test behind ``CALIB_CB_FAST_CHECK``) runs on small
   copies, smallest first (:func:`check_widths`): a :data:`CHECK_WIDTH`-pixel copy, the
   coarse image, and for boards of many squares on large images a copy wide enough that
   a board spanning :data:`MIN_BOARD_FRACTION` of the image still shows squares of
   :data:`CHECK_SQUARE_PX` pixels (the check ignores blobs under 10 px). Frames without a
   board fail in tens of milliseconds instead of the seconds a full search takes (clutter
   of many equal blobs, such as a tiled wall, can pass the check and cost a search); a
   board first seen at the widest copy is searched for on that copy. The corners are
   mapped back to full resolution.
2. **Gradient refinement** at full resolution with ``cornerSubPix``, its window sized from
   the board's square size in pixels (:data:`WINDOW_FRACTION` of the smallest corner
   spacing) instead of a fixed 11x11: a fixed large window reaches into the neighbouring
   squares on small boards and biases the corners.
3. **Saddle-point refinement** (:func:`refine_saddle`): a weighted quadratic surface is
   fitted to the lightly blurred image around each corner and the corner moved to the
   surface's saddle point, a few times. On OpenCV's sample photographs this gives a lower
   calibration RMS than both ``cornerSubPix(11x11)`` and ``findChessboardCornersSB``.

Corners are returned row by row (``cols`` corners along the board's x axis, then the next
row), normalised so that the board's x axis points to the right in the image (see
:func:`normalise_order`), which makes the ordering consistent across the images of a
sequence and across the cameras of a rig.

All coordinates are pixels with OpenCV's convention: the centre of the top-left pixel is
(0, 0). Everything here is pure computation on arrays: no files, no printing.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "COARSE_WIDTH",
    "DETECTOR_VERSION",
    "WINDOW_FRACTION",
    "check_widths",
    "corner_spacing_px",
    "detect_checkerboard",
    "normalise_order",
    "refine_saddle",
]

#: Recorded in detection caches: bump when the detector's output can change.
DETECTOR_VERSION = "acscal-checkerboard-4"
#: Width (pixels) of the image the coarse search runs on.
COARSE_WIDTH = 640
#: ``cornerSubPix`` half-window as a fraction of the smallest corner spacing.
WINDOW_FRACTION = 0.3
#: Saddle-point fit radius as a fraction of the smallest corner spacing.
SADDLE_FRACTION = 0.15

#: Width (pixels) of the image of the first quick "is there a board?" check.
CHECK_WIDTH = 320
#: Square size (pixels) the quick check needs to see a board reliably.
CHECK_SQUARE_PX = 13
#: Smallest board (squares and margin, as a fraction of the image width) the quick checks
#: are sized for: smaller boards may be reported as "no board".
MIN_BOARD_FRACTION = 0.25

_COARSE_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH  # NORMALIZE_IMAGE: slower, no gain here
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)


def corner_spacing_px(corners: NDArray[np.floating], cols: int, rows: int) -> float:
    """The smallest distance between neighbouring corners, in pixels.

    Parameters
    ----------
    corners : ndarray, shape (cols * rows, 2)
        Corners row by row, pixels.
    cols, rows : int
        Inner corners along the board's x and y axes.

    Returns
    -------
    float
        The smallest spacing along rows and columns (pixels); a proxy of the square size
        in the image at its most foreshortened.
    """
    g = np.asarray(corners, dtype=float).reshape(rows, cols, 2)
    dx = np.linalg.norm(np.diff(g, axis=1), axis=2)
    dy = np.linalg.norm(np.diff(g, axis=0), axis=2)
    return float(min(dx.min() if dx.size else np.inf, dy.min() if dy.size else np.inf))


def normalise_order(corners: NDArray[np.floating], cols: int, rows: int) -> NDArray[np.float64]:
    """Reverse the corner order if needed so that the board's x axis points right.

    A checkerboard of ``cols != rows`` inner corners is symmetric under a 180-degree
    rotation, so detectors may return its corners in either of two orders. The rule: the
    vector from the first to the last corner of the first row (the board's x axis in the
    image) must have a positive image x component (or, if it is vertical to within
    1e-9 px, point down). Both orders describe a right-handed board frame.

    Parameters
    ----------
    corners : ndarray, shape (cols * rows, 2)
        Corners row by row, pixels.
    cols, rows : int
        Inner corners along the board's x and y axes.

    Returns
    -------
    ndarray, shape (cols * rows, 2)
        The corners, possibly in reverse order (float64).
    """
    c = np.asarray(corners, dtype=float).reshape(cols * rows, 2)
    axis = c[cols - 1] - c[0]
    if axis[0] < -1e-9 or (abs(axis[0]) <= 1e-9 and axis[1] < 0):
        c = c[::-1]
    return np.ascontiguousarray(c)


def refine_saddle(
    gray: NDArray[np.generic],
    corners: NDArray[np.floating],
    radius: int,
    iterations: int = 3,
    blur_sigma: float = 1.0,
) -> NDArray[np.float64]:
    """Move each corner to the saddle point of a quadratic fitted to the image around it.

    Around each corner the (Gaussian-blurred) intensity ``I(x, y)`` is fitted, by least
    squares weighted with a Gaussian of sigma ``radius / 1.5``, with
    ``a x^2 + b x y + c y^2 + d x + e y + f``; the corner moves to the stationary point
    ``-H^-1 g`` when the surface is a saddle (``4ac - b^2 < 0``) and the step is shorter
    than ``radius``. All corners are fitted at once (one ``cv2.remap`` per iteration).

    Parameters
    ----------
    gray : ndarray, shape (h, w)
        Single-channel image (any numeric dtype).
    corners : ndarray, shape (n, 2)
        Start positions, pixels; should be within ~``radius / 2`` of the truth.
    radius : int
        Half-size of the fitted patch, pixels (the patch is ``2 radius + 1`` square).
    iterations : int
        Fit-and-move rounds.
    blur_sigma : float
        Sigma (pixels) of the Gaussian blur applied before fitting; 0 disables it.

    Returns
    -------
    ndarray, shape (n, 2)
        Refined corners (float64). Corners whose fit is not a saddle stay where they were.
    """
    img = np.asarray(gray, dtype=np.float32)
    pts = np.asarray(corners, dtype=float).reshape(-1, 2).copy()
    n = pts.shape[0]
    if n == 0:
        return pts
    r = max(int(radius), 1)
    # blur only the bounding box of the corners (plus a margin): cheaper on large images
    margin = r + 4 + int(np.ceil(3 * blur_sigma))
    x0 = max(int(np.floor(pts[:, 0].min())) - margin, 0)
    y0 = max(int(np.floor(pts[:, 1].min())) - margin, 0)
    x1 = min(int(np.ceil(pts[:, 0].max())) + margin + 1, img.shape[1])
    y1 = min(int(np.ceil(pts[:, 1].max())) + margin + 1, img.shape[0])
    roi = img[y0:y1, x0:x1]
    if blur_sigma > 0:
        roi = np.asarray(cv2.GaussianBlur(roi, (0, 0), blur_sigma), np.float32)
    offset = np.array([x0, y0], dtype=float)
    local = pts - offset

    k = 2 * r + 1
    ys, xs = np.mgrid[-r : r + 1, -r : r + 1].astype(float)
    xs, ys = xs.ravel(), ys.ravel()
    A = np.column_stack([xs**2, xs * ys, ys**2, xs, ys, np.ones_like(xs)])
    w = np.exp(-(xs**2 + ys**2) / (2.0 * (r / 1.5) ** 2))
    # weighted least squares: coefficients = P @ patch, with P = (A^T W A)^-1 A^T W
    P = np.linalg.solve((A * w[:, None]).T @ A, (A * w[:, None]).T)
    for _ in range(iterations):
        mx = (local[:, 0, None] + xs[None, :]).astype(np.float32).reshape(n, k * k)
        my = (local[:, 1, None] + ys[None, :]).astype(np.float32).reshape(n, k * k)
        patches = np.asarray(
            cv2.remap(roi, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), float
        )
        coef = patches.astype(float) @ P.T  # (n, 6): a b c d e f
        a, b, c, d, e = (coef[:, i] for i in range(5))
        det = 4.0 * a * c - b * b
        ok = det < -1e-12
        safe = np.where(ok, det, 1.0)
        dx = (-2.0 * c * d + b * e) / safe
        dy = (-2.0 * a * e + b * d) / safe
        ok &= (np.abs(dx) < r) & (np.abs(dy) < r)
        local[ok, 0] += dx[ok]
        local[ok, 1] += dy[ok]
        if not np.any(ok) or max(np.abs(dx[ok]).max(), np.abs(dy[ok]).max()) < 1e-3:
            break
    return local + offset


def _to_gray(image: NDArray[np.generic]) -> NDArray[np.uint8]:
    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if img.dtype != np.uint8:
        f = img.astype(float)
        lo, hi = float(f.min()), float(f.max())
        img = np.zeros(f.shape, np.uint8) if hi <= lo else ((f - lo) * (255.0 / (hi - lo)))
        img = np.clip(np.round(img), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(img)


def check_widths(width: int, cols: int, rows: int, coarse_width: int = COARSE_WIDTH) -> list[int]:
    """Widths (pixels) of the copies the quick board check runs on, smallest first.

    :data:`CHECK_WIDTH` if a board filling the image shows squares of at least
    :data:`CHECK_SQUARE_PX` there; the coarse search's width; and, for boards of many
    squares, the width at which a board spanning :data:`MIN_BOARD_FRACTION` of the image
    shows such squares (at most ``width``). The board's long side is taken along the
    image's width, with one square of margin each side.

    Parameters
    ----------
    width : int
        The image's width, pixels.
    cols, rows : int
        Inner corners of the board.
    coarse_width : int
        Width of the coarse search's image.

    Returns
    -------
    list of int
        Increasing widths, each at most ``width``.
    """
    span = max(cols, rows) + 3  # squares across the printed board, margin included
    small = min(width, coarse_width)
    out = []
    if width > CHECK_WIDTH and CHECK_WIDTH < small and CHECK_WIDTH >= CHECK_SQUARE_PX * span:
        out.append(CHECK_WIDTH)
    out.append(small)
    fine = min(width, int(np.ceil(CHECK_SQUARE_PX * span / MIN_BOARD_FRACTION)))
    if fine > 1.2 * small:
        out.append(fine)
    return out


def _downscale(gray: NDArray[np.uint8], width: int) -> NDArray[np.uint8]:
    h, w = gray.shape[:2]
    if width >= w:
        return gray
    size = (width, max(round(h * width / w), 1))
    return np.asarray(cv2.resize(gray, size, interpolation=cv2.INTER_AREA), np.uint8)


def _quick_check(
    gray: NDArray[np.uint8], cols: int, rows: int, coarse_width: int
) -> NDArray[np.uint8] | None:
    """``cv2.checkChessboard`` (what ``CALIB_CB_FAST_CHECK`` runs) on small copies first.

    The check runs at each of :func:`check_widths` in turn (a few to a few tens of
    milliseconds each) until one sees a board. Returns the image the coarse search should
    run on (the coarse copy, or the wider copy where the board was first seen), or None
    when no copy shows a board.
    """
    widths = check_widths(gray.shape[1], cols, rows, coarse_width)
    small = _downscale(gray, min(gray.shape[1], coarse_width))
    for cw in widths:
        img = small if cw == small.shape[1] else _downscale(gray, cw)
        if cv2.checkChessboard(img, (cols, rows)):
            return small if cw <= small.shape[1] else img
    return None


def detect_checkerboard(
    image: NDArray[np.generic],
    cols: int,
    rows: int,
    *,
    coarse_width: int = COARSE_WIDTH,
    saddle: bool = True,
) -> NDArray[np.float64] | None:
    """Find a checkerboard's inner corners with sub-pixel accuracy.

    Parameters
    ----------
    image : ndarray, shape (h, w) or (h, w, 3)
        The image (grey or BGR; any numeric dtype, rescaled to 8 bits).
    cols, rows : int
        Inner corners along the board's x axis (per row) and y axis (>= 2 each).
    coarse_width : int
        Width of the downscaled image of the coarse search (pixels); images at most this
        wide are searched at full resolution.
    saddle : bool
        Run the saddle-point refinement after ``cornerSubPix``.

    Returns
    -------
    ndarray, shape (cols * rows, 2) or None
        Corners row by row in pixels, the board's x axis pointing right in the image; the
        first corner is the board frame's origin. None if no complete board is found.

    Raises
    ------
    ValueError
        If ``cols`` or ``rows`` is below 2 (a programming error: the CLI checks it).
    """
    if cols < 2 or rows < 2:
        raise ValueError(f"a board needs at least 2x2 inner corners, got {cols}x{rows}")
    gray = _to_gray(image)
    h, w = gray.shape[:2]
    small = _quick_check(gray, cols, rows, coarse_width)
    if small is None:
        return None
    scale = w / float(small.shape[1])
    scale_y = h / float(small.shape[0])
    found, coarse = cv2.findChessboardCorners(small, (cols, rows), flags=_COARSE_FLAGS)
    if not found or coarse is None or coarse.shape[0] != cols * rows:
        return None
    c = coarse.reshape(-1, 2).astype(float)
    if scale != 1.0:
        c[:, 0] = (c[:, 0] + 0.5) * scale - 0.5
        c[:, 1] = (c[:, 1] + 0.5) * scale_y - 0.5
    spacing = corner_spacing_px(c, cols, rows)
    if not np.isfinite(spacing) or spacing < 4.0:
        return None
    half = int(np.clip(round(WINDOW_FRACTION * spacing), 2, 25))
    # coarse corners from a downscaled image are off by up to ~scale px: one wide pass first
    if scale > 1.5:
        wide = int(np.clip(round(0.45 * spacing), half, 40))
        c = cv2.cornerSubPix(
            gray, c.astype(np.float32).reshape(-1, 1, 2), (wide, wide), (-1, -1), _SUBPIX_CRITERIA
        ).reshape(-1, 2)
    c = cv2.cornerSubPix(
        gray, np.asarray(c, np.float32).reshape(-1, 1, 2), (half, half), (-1, -1), _SUBPIX_CRITERIA
    ).reshape(-1, 2)
    out = np.asarray(c, dtype=float)
    if saddle:
        radius = int(np.clip(round(SADDLE_FRACTION * spacing), 3, 20))
        out = refine_saddle(gray, out, radius, blur_sigma=max(1.0, 0.5 * scale))
    if not np.all(np.isfinite(out)):
        return None
    return normalise_order(out, cols, rows)
