"""Checkerboard corner detection: a fast coarse search, then an accurate sub-pixel refinement.

The detector (:func:`detect_checkerboard`) works in three steps:

1. **Coarse search** on a pyramid of the image, each level half the size of the one above
   (exact 2x2 pixel averages: cheap to make, and a level's corners map back to full
   resolution exactly), with OpenCV's classic ``findChessboardCorners`` (adaptive
   threshold; no image normalisation, which costs time and gained nothing). The levels
   tried are :func:`check_levels`', smallest image first: one about :data:`CHECK_WIDTH`
   pixels wide when a board filling the image shows squares of :data:`CHECK_SQUARE_PX`
   pixels there, the search level (about :data:`COARSE_WIDTH` wide, or wider where a board
   spanning :data:`TYPICAL_BOARD_FRACTION` of the image needs it to show such squares),
   and for boards of many squares on large images one wide enough that a board spanning
   :data:`MIN_BOARD_FRACTION` of the image does (the quick checks ignore blobs under
   10 px). Below the search level only ``cv2.checkChessboard`` runs, a board it sees being
   searched for on the search level; from the search level on the search runs with
   ``CALIB_CB_FAST_CHECK``. Frames without a board fail in tens of milliseconds instead of
   the seconds a full search takes (clutter of many equal blobs, such as a tiled wall, can
   pass the check and cost a search).
2. **X-junction fit** (:func:`refine_x_junction`) at full resolution: around each corner,
   within a radius of :data:`FIT_FRACTION` of the corner spacing, the image is fitted by
   least squares with the model of a blurred checkerboard corner, ``m + a tanh(d1 / s)
   tanh(d2 / s)`` (``d1``, ``d2`` the distances to the board's two edge lines through the
   corner), and the corner moved to the fitted junction. It uses every pixel of the
   corner's neighbourhood, not only its gradients, and on real photographs reaches a lower
   calibration RMS than ``findChessboardCornersSB`` with ``CALIB_CB_ACCURACY``
   (``benchmarks/bench_detection_real.py``). When the search level is at most 2x
   downscaled the fit starts at the coarse corners (``findChessboardCorners`` refines them
   on its level), each corner until a round moves it less than :data:`FIT_STOP` pixels
   (at most :data:`FIT_ROUNDS` rounds).
3. **Gradient refinement**, where the fit cannot start at the coarse corners:
   ``cornerSubPix`` on a copy of the board's region blurred by :data:`BLUR_SIGMA` pixels
   (which removes the pixel-periodic demosaicing and aliasing patterns of real cameras
   that bias gradients), its window sized from the board's square size in pixels
   (:data:`WINDOW_FRACTION` of the smallest corner spacing) instead of a fixed 11x11 (a
   fixed large window reaches into the neighbouring squares on small boards and biases the
   corners). It runs before the fit when the search level is 4x or more downscaled (with
   a wider window first), on the corners the fit moved more than :data:`MAX_FIT_SHIFT`
   pixels of the search level from their start (blurred frames, where the coarse corners
   can be pixels off; these are fitted again from there and keep ``cornerSubPix``'s
   estimate if the fit moves them more than :data:`MAX_FIT_SHIFT` pixels), and alone with
   ``fit=False``.

:func:`refine_saddle` (a quadratic surface fitted around each corner, moved to its saddle
point) is the refinement of detectors before ``acscal-checkerboard-5``, kept for the corners
of :mod:`acs_cli.core.targets`.

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
    "FIT_FRACTION",
    "WINDOW_FRACTION",
    "check_levels",
    "check_widths",
    "corner_spacing_px",
    "detect_checkerboard",
    "downscaled",
    "normalise_order",
    "refine_saddle",
    "refine_x_junction",
]

#: Recorded in detection caches: bump when the detector's output can change.
DETECTOR_VERSION = "acscal-checkerboard-7"
#: Width (pixels) about which the coarse search runs (the first pyramid level at least
#: :data:`LEVEL_SLACK` times as wide), unless the board's squares need a wider one.
COARSE_WIDTH = 640
#: ``cornerSubPix`` half-window as a fraction of the smallest corner spacing.
WINDOW_FRACTION = 0.3
#: Sigma (pixels) of the blur of the copy ``cornerSubPix`` runs on.
BLUR_SIGMA = 1.0
#: X-junction fit radius as a fraction of the smallest corner spacing.
FIT_FRACTION = 0.4
#: Most inner corners along a board's side that acscal accepts (OpenCV's pattern sizes are
#: 32-bit; no printable board comes near).
MAX_BOARD_CORNERS = 1000
#: Edge width ``s`` (pixels) of the X-junction model ``tanh(d / s)``.
EDGE_WIDTH = 1.0
#: Most rounds of the X-junction fit in :func:`detect_checkerboard`: from the coarse
#: corners on blurred images its steps fall short and take several rounds to converge.
FIT_ROUNDS = 4
#: A corner's fit stops when a round moves it less than this (pixels).
FIT_STOP = 0.01
#: Largest move the X-junction fit may make from its start, in pixels of the image the
#: start comes from (the search level for coarse corners, else full resolution).
MAX_FIT_SHIFT = 0.75

#: Width (pixels) of the image of the first quick "is there a board?" check.
CHECK_WIDTH = 320
#: Square size (pixels) the quick check needs to see a board reliably.
CHECK_SQUARE_PX = 13
#: Smallest board (squares and margin, as a fraction of the image width) the quick checks
#: are sized for: smaller boards may be reported as "no board".
MIN_BOARD_FRACTION = 0.25
#: A board spanning this fraction of the image width should pass the second check.
TYPICAL_BOARD_FRACTION = 0.5
#: A check at width ``t`` runs on the smallest pyramid level at least this times ``t`` wide.
LEVEL_SLACK = 0.8

_COARSE_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH  # NORMALIZE_IMAGE: slower, no gain here
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 1e-3)
# before the X-junction fit, cornerSubPix only needs to bring corners within its reach
_SUBPIX_COARSE_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 10, 0.05)


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


#: A coarse corner further than this fraction of the local corner spacing from the board's
#: smooth grid (:func:`smooth_grid`) is re-seeded on it.
RESEED_FRACTION = 0.25


def _cubic_terms(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """The ten monomials of degree <= 3 in ``x``, ``y`` (shape (n,) each), shape (n, 10)."""
    return np.column_stack(
        [np.ones_like(x), x, y, x * x, x * y, y * y, x**3, x * x * y, x * y * y, y**3]
    )


def smooth_grid(
    corners: NDArray[np.floating], cols: int, rows: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]] | None:
    """The board's grid as a smooth map of its corners, fitted so that a few wrong corners
    do not move it.

    The map is a homography from the grid's indices to the image (``cv2.findHomography``
    with RANSAC: perspective) plus a cubic polynomial of the indices (lens distortion, which
    is smooth over a board), fitted by least squares on the corners within three robust
    standard deviations (and 0.05 px) of the last fit, until they no longer change (at most
    five fits).

    Parameters
    ----------
    corners : ndarray, shape (cols * rows, 2)
        Corners row by row, pixels.
    cols, rows : int
        Inner corners along the board's x and y axes.

    Returns
    -------
    grid : ndarray, shape (cols * rows, 2)
        Where the map puts each corner, pixels.
    spacing : ndarray, shape (cols * rows,)
        The map's smaller step between neighbouring corners there, pixels.
    Or None when the board has under 16 corners (too few to tell a wrong one) or no
    homography fits.
    """
    c = np.asarray(corners, dtype=float).reshape(-1, 2)
    if c.shape[0] < 16 or not np.all(np.isfinite(c)):
        return None
    jj, ii = np.meshgrid(np.arange(rows, dtype=float), np.arange(cols, dtype=float), indexing="ij")
    obj = np.column_stack([ii.ravel(), jj.ravel()])
    # RANSAC within a quarter of the typical spacing: the homography only has to hold the
    # board's bulk (the cubic takes up the distortion); LMEDS costs 4x as much
    typical = float(np.median(np.linalg.norm(np.diff(c.reshape(rows, cols, 2), axis=1), axis=2)))
    H, _ = cv2.findHomography(obj, c, cv2.RANSAC, max(RESEED_FRACTION * typical, 1.0))
    if H is None:
        return None
    base = np.asarray(cv2.perspectiveTransform(obj[:, None, :], H), float).reshape(-1, 2)
    # the polynomial on indices scaled to [-1, 1] (well-conditioned); skipped on boards too
    # small to hold it with room to spare
    A = _cubic_terms(
        (obj[:, 0] - 0.5 * (cols - 1)) / max(0.5 * (cols - 1), 1.0),
        (obj[:, 1] - 0.5 * (rows - 1)) / max(0.5 * (rows - 1), 1.0),
    )
    r = c - base
    fit = np.zeros_like(r)
    if c.shape[0] >= 3 * A.shape[1]:
        w = np.ones(c.shape[0], dtype=bool)
        for _ in range(5):
            coef = np.linalg.lstsq(A[w], r[w], rcond=None)[0]
            fit = A @ coef
            e = np.linalg.norm(r - fit, axis=1)
            kept = e <= 3.0 * 1.4826 * float(np.median(e)) + 0.05
            if np.array_equal(kept, w):
                break  # the same corners again: the same fit
            w = kept
    grid = base + fit
    g = grid.reshape(rows, cols, 2)
    step_x = np.linalg.norm(np.gradient(g, axis=1), axis=2)
    step_y = np.linalg.norm(np.gradient(g, axis=0), axis=2)
    return grid, np.minimum(step_x, step_y).ravel()


def _off_grid(
    corners: NDArray[np.float64], smooth: tuple[NDArray[np.float64], NDArray[np.float64]]
) -> NDArray[np.bool_]:
    """The corners further than :data:`RESEED_FRACTION` of the local spacing from the
    smooth grid ``(grid, spacing)`` of :func:`smooth_grid`."""
    grid, step = smooth
    return np.asarray(np.linalg.norm(corners - grid, axis=1) > RESEED_FRACTION * step)


def reseed_outliers(
    corners: NDArray[np.floating], cols: int, rows: int
) -> tuple[
    NDArray[np.float64],
    NDArray[np.bool_],
    tuple[NDArray[np.float64], NDArray[np.float64]] | None,
]:
    """Move corners far off the board's smooth grid onto it (:func:`smooth_grid`).

    A corner further than :data:`RESEED_FRACTION` of the local spacing from the grid is
    placed on it: through motion blur a coarse search can put a few corners along the
    board's border several pixels off, and from there no local refinement finds the
    corner. Elsewhere the grid is within a fraction of a pixel of the corner, well inside
    the refinement's reach.

    Returns
    -------
    corners : ndarray, shape (cols * rows, 2)
    moved : ndarray of bool, shape (cols * rows,)
    smooth : (grid, spacing) of :func:`smooth_grid`, or None where it has none
    """
    c = np.asarray(corners, dtype=float).reshape(-1, 2).copy()
    smooth = smooth_grid(c, cols, rows)
    if smooth is None:
        return c, np.zeros(c.shape[0], dtype=bool), None
    moved = _off_grid(c, smooth)
    c[moved] = smooth[0][moved]
    return c, moved, smooth


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
        # einsum, not a BLAS product: OpenBLAS threads stall on a loaded machine
        coef = np.einsum("nk,mk->nm", patches, P)  # (n, 6): a b c d e f
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


def _edge_normals(
    corners: NDArray[np.float64], cols: int, rows: int
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Angles (radians) of the normals of the board's two edge lines through each corner.

    The line along the board's x axis at a corner runs towards its row neighbours, the other
    towards its column neighbours (central differences inside the grid, one-sided at its
    border); each normal is the line's direction turned by 90 degrees.
    """
    g = corners.reshape(rows, cols, 2)
    along_x = np.asarray(np.gradient(g, axis=1))
    along_y = np.asarray(np.gradient(g, axis=0))
    t1 = np.arctan2(along_x[..., 1], along_x[..., 0]) + 0.5 * np.pi
    t2 = np.arctan2(along_y[..., 1], along_y[..., 0]) + 0.5 * np.pi
    return t1.ravel(), t2.ravel()


def _disc_samples(radius: float, spacing: float) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """Sample offsets (pixels) on a disc, point-symmetric about its centre, shape (1, p) each.

    A sunflower (golden-angle) spiral and its mirror image, one sample per ``spacing^2``
    square pixels: no two samples share a row or column, so an edge along the image's rows
    or columns is seen at every sub-pixel phase (a square grid would see it at one phase
    only and lock the fit to it).
    """
    half = max(round(np.pi * radius**2 / spacing**2 / 2), 4)
    i = np.arange(half) + 0.5
    r = radius * np.sqrt(i / half)
    a = i * np.pi * (3.0 - np.sqrt(5.0))
    x, y = r * np.cos(a), r * np.sin(a)
    u = np.concatenate([x, -x]).astype(np.float32)[None, :]
    v = np.concatenate([y, -y]).astype(np.float32)[None, :]
    return u, v


def _tanh_inplace(x: NDArray[np.float32]) -> NDArray[np.float32]:
    """``tanh(x)`` in place, as ``2 / (1 + exp(-2 x)) - 1``: ``cv2.exp`` is vectorised,
    several times faster than ``np.tanh`` on float32 (overflow to inf gives -1, exactly)."""
    x *= np.float32(-2.0)
    cv2.exp(x, x)
    x += np.float32(1.0)
    np.divide(np.float32(2.0), x, out=x)
    x -= np.float32(1.0)
    return x


def _step_gain(first: NDArray[np.float64], second: NDArray[np.float64]) -> float:
    """The factor the fit's steps should be scaled by, from two rounds' steps.

    On an image blurred more than the model, each step covers a fraction ``g`` of the way
    to the junction (the same on the whole board), so the second step is about ``1 - g``
    times the first: ``1 / g`` from the median ratio over the corners whose first step
    stands above the noise (0.05 px); 1 if fewer than 4 do, at most 4.
    """
    norm2 = np.sum(first * first, axis=1)
    big = norm2 > 0.05**2
    if np.count_nonzero(big) < 4:
        return 1.0
    ratio = float(np.median(np.sum(first[big] * second[big], axis=1) / norm2[big]))
    return 1.0 / (1.0 - min(max(ratio, 0.0), 0.75))


def refine_x_junction(
    gray: NDArray[np.generic],
    corners: NDArray[np.floating],
    cols: int,
    rows: int,
    radius: float,
    *,
    iterations: int = 3,
    tolerance: float = 1e-3,
) -> NDArray[np.float64]:
    """Fit the model of a blurred checkerboard corner to the image around each corner.

    Around corner ``c`` the image is modelled as ``I(p) = m + a tanh(d1 / s) tanh(d2 / s)``
    with ``d1 = n1 . (p - c)`` and ``d2 = n2 . (p - c)`` the signed distances (pixels) to
    the board's two edge lines through ``c`` (their normals ``n1``, ``n2`` from the
    directions to the corner's grid neighbours) and ``s`` the edge width
    (:data:`EDGE_WIDTH`). Samples on a disc of ``radius`` pixels, weighted by a Gaussian of
    sigma ``radius / 1.5``, fit ``m``, ``a`` and the shift of ``c`` by linear least squares
    on the model linearised in ``c`` (one Gauss-Newton step); the corner moves, the disc is
    sampled again (bilinear) and the step repeated. The edge lines' directions and ``s``
    stay fixed: the model and a corner's image are both symmetric under a half turn about
    the corner, so errors in them do not move the fitted junction to first order. All
    corners are fitted at once; a corner stops when a round moves it less than
    ``tolerance``. On an image blurred more than the model the steps fall short of the
    junction by a factor common to the board: from the third round on they are scaled by the
    gain :func:`_step_gain` reads from the first two rounds' steps (1 on sharp images).

    Samples lie on a sunflower spiral and its mirror image, one per 1.5 x 1.5 px (1 x 1 px
    when ``radius`` is under 6 px): not on a square grid, which would see edges along the
    image axes at a single sub-pixel phase, nor 2 px apart, which would alias with the
    2-pixel periodic demosaicing patterns of colour cameras.

    Parameters
    ----------
    gray : ndarray, shape (h, w)
        Single-channel image (any numeric dtype), not blurred. An 8-bit image is sampled
        as it is, its interpolated values rounded to whole grey levels (0.3 grey levels RMS
        of added noise, well below a camera's; cheaper than converting it).
    corners : ndarray, shape (cols * rows, 2)
        Start positions row by row, pixels; within about ``radius / 4`` of the truth (the
        corners of a coarse search at most 2x downscaled, or ``cornerSubPix``'s).
    cols, rows : int
        Inner corners along the board's x and y axes (>= 2 each).
    radius : float
        Radius of the fitted disc, pixels (>= 2); about 0.4 of the corner spacing.
    iterations : int
        Most fit-and-move rounds (>= 1).
    tolerance : float
        A corner stops when a round moves it less than this along both axes (pixels).

    Returns
    -------
    ndarray, shape (cols * rows, 2)
        Refined corners, pixels (float64). A corner whose fit has no contrast (``|a|``
        under one grey level) does not move; a move is at most 1 px per round.

    Raises
    ------
    ValueError
        If the corners are not ``cols x rows``, ``radius < 2`` or ``iterations < 1``.
    """
    c = np.asarray(corners, dtype=float).reshape(-1, 2).copy()
    if cols < 2 or rows < 2 or c.shape[0] != cols * rows:
        raise ValueError(f"expected {cols}x{rows} >= 2x2 corners, got {c.shape[0]}")
    if radius < 2 or iterations < 1:
        raise ValueError(f"need radius >= 2 and iterations >= 1; got {radius}, {iterations}")
    img = np.asarray(gray)
    if img.dtype != np.uint8:  # 8-bit images are sampled as they are: cheaper
        img = img.astype(np.float32)
    u, v = _disc_samples(radius, 1.5 if radius >= 6 else 1.0)
    # the second half of the samples mirrors the first: the model's terms are computed on
    # the first half only (the shape and the constant are even about the corner, the
    # derivatives odd), the image's samples folded into their even and odd parts
    half = u.shape[1] // 2
    uh, vh = u[:, :half], v[:, :half]
    w = np.exp(-(uh**2 + vh**2) / (2.0 * (radius / 1.5) ** 2)).astype(np.float32)
    t1, t2 = _edge_normals(c, cols, rows)
    n1x, n1y, n2x, n2y = (
        np.asarray(f(t) / EDGE_WIDTH, np.float32)[:, None]
        for t in (t1, t2)
        for f in (np.cos, np.sin)
    )
    e1 = _tanh_inplace(n1x * uh + n1y * vh)  # tanh(d1 / s)
    e2 = _tanh_inplace(n2x * uh + n2y * vh)
    shape = e1 * e2
    # derivatives of tanh(d1/s) tanh(d2/s) with respect to the corner (d = n . (p - c)):
    # (1 - e1^2) e2 = e2 - e1 shape, and the same for e2
    g1 = e2 - e1 * shape
    g2 = e1 - e2 * shape
    jx = g1 * -n1x - g2 * n2x
    jy = g1 * -n1y - g2 * n2y
    # On the disc the normal equations split into two 2x2 systems, one for (m, a), one for
    # a times the shift; the mirrored halves' factors 2 cancel in each solution.
    w_s, w_x, w_y = w * shape, w * jx, w * jy

    def dot(p: NDArray[np.float32], q: NDArray[np.float32]) -> NDArray[np.float64]:
        return np.asarray(np.einsum("ij,ij->i", p, q), np.float64)  # per corner, no temporary

    sw = float(np.sum(w))
    s1, ss = np.asarray(shape @ w[0], np.float64), dot(w_s, shape)
    xx, xy, yy = dot(w_x, jx), dot(w_x, jy), dot(w_y, jy)
    det_a = sw * ss - s1 * s1
    det_s = xx * yy - xy * xy
    good = (det_a > 1e-9 * sw * ss) & (det_s > 1e-9 * xx * yy)
    per_corner = np.column_stack([s1, det_a, xx, xy, yy, det_s])
    active = np.flatnonzero(good)  # the corners still moving
    steps = np.zeros((2, c.shape[0], 2))  # each corner's first two moves
    gain = 1.0
    for k in range(iterations):
        if active.size == 0:
            break
        every = active.size == c.shape[0]
        ws, wx, wy = (t if every else t[active] for t in (w_s, w_x, w_y))
        s1_, da, xx_, xy_, yy_, ds = (per_corner if every else per_corner[active]).T
        c32 = c[active].astype(np.float32)
        mx, my = c32[:, 0, None] + u, c32[:, 1, None] + v
        patch = np.asarray(
            cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE), np.float32
        )
        even = patch[:, :half] + patch[:, half:]
        odd = patch[:, :half] - patch[:, half:]
        p0, ps = np.asarray(even @ w[0], np.float64), dot(ws, even)
        px, py = dot(wx, odd), dot(wy, odd)
        amp = (sw * ps - s1_ * p0) / da
        sx = (yy_ * px - xy_ * py) / ds  # a times the shift
        sy = (xx_ * py - xy_ * px) / ds
        ok = np.abs(amp) >= 1.0
        safe = np.where(ok, amp, 1.0)
        shift = np.column_stack([sx / safe, sy / safe]) * gain
        shift = np.clip(shift, -1.0, 1.0)
        shift[~ok] = 0.0
        c[active] += shift
        if k < 2:
            steps[k, active] = shift
        if k == 1:
            gain = _step_gain(steps[0], steps[1])
        active = active[np.abs(shift).max(axis=1) >= tolerance]
    return c


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


def check_widths(width: int, cols: int, rows: int) -> list[int]:
    """Widths (pixels) the quick board check should see the image at, smallest first.

    :data:`CHECK_WIDTH` if a board filling the image shows squares of at least
    :data:`CHECK_SQUARE_PX` there; :data:`COARSE_WIDTH`, or the width at which a board spanning
    :data:`TYPICAL_BOARD_FRACTION` of the image shows such squares if that is wider; and,
    for boards of many squares, the width at which a board spanning
    :data:`MIN_BOARD_FRACTION` of the image does. Each is at most ``width``. The board's
    long side is taken along the image's width, with one square of margin each side.

    Parameters
    ----------
    width : int
        The image's width, pixels.
    cols, rows : int
        Inner corners of the board.

    Returns
    -------
    list of int
        Increasing widths, each at most ``width``.
    """
    span = max(cols, rows) + 3  # squares across the printed board, margin included
    mid = _search_width(width, cols, rows)
    out = []
    if width > CHECK_WIDTH and CHECK_WIDTH < mid and CHECK_WIDTH >= CHECK_SQUARE_PX * span:
        out.append(CHECK_WIDTH)
    out.append(mid)
    fine = min(width, int(np.ceil(CHECK_SQUARE_PX * span / MIN_BOARD_FRACTION)))
    if fine > 1.2 * mid:
        out.append(fine)
    return out


def _search_width(width: int, cols: int, rows: int) -> int:
    """The second width of :func:`check_widths`, about which the coarse search runs."""
    span = max(cols, rows) + 3
    typical = int(np.ceil(CHECK_SQUARE_PX * span / TYPICAL_BOARD_FRACTION))
    return min(width, max(COARSE_WIDTH, typical))


def _level(width: int, target: float) -> int:
    """The smallest pyramid level at least :data:`LEVEL_SLACK` times ``target`` wide."""
    level = 0
    while (width >> (level + 1)) >= LEVEL_SLACK * target:
        level += 1
    return level


def check_levels(width: int, cols: int, rows: int) -> list[int]:
    """Pyramid levels the quick board check runs on, smallest image first.

    Level ``L`` is the image halved ``L`` times (``width >> L`` pixels wide). Each width of
    :func:`check_widths` maps to the smallest level at least :data:`LEVEL_SLACK` times as
    wide (levels are exact 2x2 averages: cheap to make and to map back, unlike arbitrary
    sizes).

    Parameters
    ----------
    width : int
        The image's width, pixels.
    cols, rows : int
        Inner corners of the board.

    Returns
    -------
    list of int
        Decreasing levels (increasing widths), each >= 0; the last one's image is the one
        the second width of :func:`check_widths` maps to, or wider.
    """
    out: list[int] = []
    for target in check_widths(width, cols, rows):
        level = _level(width, target)
        if level not in out:
            out.append(level)
    return out


def downscaled(image: NDArray[np.uint8], width: int) -> NDArray[np.uint8]:
    """``image`` ``(h, w)`` scaled down (area averaging) to ``width`` pixels wide, the aspect
    kept; as it is when no wider."""
    h, w = image.shape[:2]
    if w <= width:
        return image
    size = (width, max(1, round(h * width / w)))
    return np.asarray(cv2.resize(image, size, interpolation=cv2.INTER_AREA), np.uint8)


def _half(img: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """The image halved by 2x2 averages (a last odd row or column is dropped)."""
    h, w = img.shape[:2]
    even = img[: h - h % 2, : w - w % 2]
    return np.asarray(cv2.resize(even, (w // 2, h // 2), interpolation=cv2.INTER_AREA), np.uint8)


def _coarse_search(
    gray: NDArray[np.uint8], cols: int, rows: int
) -> tuple[NDArray[np.float32], int] | None:
    """Quick board checks on small pyramid levels first, then the classic search.

    The levels are :func:`check_levels`'. On the search level (the search width's, see
    :func:`check_widths`) ``findChessboardCorners`` runs with ``CALIB_CB_FAST_CHECK``: when
    a board is there its binary check costs less than a separate ``checkChessboard``; when
    it fails and a wider level remains, ``checkChessboard`` tells a board it could not
    complete (stop: a partial view) from no board seen (go on). On other levels
    ``checkChessboard`` runs first, and a board it sees is searched for on that level or,
    if it is smaller, on the search level. Returns the coarse corners, shape
    (cols * rows, 1, 2) in that level's pixels, and the level; or None.
    """
    levels = check_levels(gray.shape[1], cols, rows)
    pyramid = [gray]
    while len(pyramid) <= levels[0]:
        pyramid.append(_half(pyramid[-1]))
    search_level = _level(gray.shape[1], _search_width(gray.shape[1], cols, rows))
    size = (cols, rows)
    for i, level in enumerate(levels):
        if level == search_level:
            flags = _COARSE_FLAGS | cv2.CALIB_CB_FAST_CHECK
            found, coarse = cv2.findChessboardCorners(pyramid[level], size, flags=flags)
            if not found and i + 1 < len(levels) and not cv2.checkChessboard(pyramid[level], size):
                continue
        else:
            if not cv2.checkChessboard(pyramid[level], size):
                continue
            level = min(level, search_level)
            found, coarse = cv2.findChessboardCorners(pyramid[level], size, flags=_COARSE_FLAGS)
        if not found or coarse is None or coarse.shape[0] != cols * rows:
            return None
        return np.asarray(coarse, np.float32), level
    return None


def _subpix(
    roi: NDArray[np.uint8],
    corners: NDArray[np.float64],
    windows: tuple[int, ...],
    criteria: tuple[int, int, float],
) -> NDArray[np.float64]:
    """``cornerSubPix`` on ``roi`` blurred by :data:`BLUR_SIGMA`, one pass per half-window.

    The last pass uses ``criteria``, the others full convergence. Returns the corners,
    shape (n, 2), float64.
    """
    blurred = np.asarray(cv2.GaussianBlur(roi, (0, 0), BLUR_SIGMA), np.uint8)
    pts = np.asarray(corners, np.float32).reshape(-1, 1, 2)
    for i, win in enumerate(windows):
        crit = criteria if i == len(windows) - 1 else _SUBPIX_CRITERIA
        pts = np.asarray(cv2.cornerSubPix(blurred, pts, (win, win), (-1, -1), crit), np.float32)
    return np.asarray(pts, dtype=float).reshape(-1, 2)


def _fit(
    roi: NDArray[np.uint8],
    start: NDArray[np.float64],
    cols: int,
    rows: int,
    radius: float,
    tolerance: float,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """:func:`refine_x_junction` (:data:`FIT_ROUNDS`, :data:`FIT_STOP`) from ``start``; a
    corner it moves more than ``tolerance`` pixels stays at ``start``. Returns the corners
    and where they stayed."""
    out = refine_x_junction(
        roi, start, cols, rows, radius, iterations=FIT_ROUNDS, tolerance=FIT_STOP
    )
    far = np.linalg.norm(out - start, axis=1) > tolerance
    out[far] = start[far]
    return out, far


def _full_search(
    gray: NDArray[np.uint8], cols: int, rows: int
) -> tuple[NDArray[np.float32], int] | None:
    """``findChessboardCorners`` on the full-resolution image without any quick check: the
    coarse corners (shape (cols * rows, 1, 2)) and level 0, or None."""
    found, coarse = cv2.findChessboardCorners(gray, (cols, rows), flags=_COARSE_FLAGS)
    if not found or coarse is None or coarse.shape[0] != cols * rows:
        return None
    return np.asarray(coarse, np.float32), 0


def detect_checkerboard(
    image: NDArray[np.generic],
    cols: int,
    rows: int,
    *,
    full_search: bool = False,
) -> NDArray[np.float64] | None:
    """Find a checkerboard's inner corners with sub-pixel accuracy.

    Parameters
    ----------
    image : ndarray, shape (h, w) or (h, w, 3)
        The image (grey or BGR; any numeric dtype, rescaled to 8 bits).
    cols, rows : int
        Inner corners along the board's x axis (per row) and y axis (>= 2 each).
    full_search : bool
        When the quick checks see no board, search the full-resolution image anyway. OpenCV's
        quick check misses boards whose squares are under about 16 px; the search finds
        them, at several hundred milliseconds on a large frame without a board (the
        stages run it on the frames that failed when the boards found are that small,
        :func:`acs_cli.stages.intrinsics.detect_folder`).

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
    seen = _coarse_search(gray, cols, rows)
    if seen is None and full_search:
        seen = _full_search(gray, cols, rows)
    if seen is None:
        return None
    coarse, level = seen
    scale = float(2**level)
    c = (coarse.reshape(-1, 2).astype(float) + 0.5) * scale - 0.5
    c, _, smooth = reseed_outliers(c, cols, rows)
    spacing = corner_spacing_px(c, cols, rows)
    if not np.isfinite(spacing) or spacing < 4.0:
        return None
    half = int(np.clip(round(WINDOW_FRACTION * spacing), 2, 25))
    wide = int(np.clip(round(0.45 * spacing), half, 40))
    radius = float(np.clip(FIT_FRACTION * spacing, 2.0, 20.0))
    # the board's region (corners, windows and blur margin)
    margin = max(wide, int(np.ceil(radius))) + 2 + int(np.ceil(3 * BLUR_SIGMA))
    x0, y0 = (max(int(np.floor(v)) - margin, 0) for v in c.min(axis=0))
    x1 = min(int(np.ceil(c[:, 0].max())) + margin + 1, gray.shape[1])
    y1 = min(int(np.ceil(c[:, 1].max())) + margin + 1, gray.shape[0])
    roi = gray[y0:y1, x0:x1]
    offset = np.array([x0, y0], dtype=float)
    coarse_local = c - offset
    # coarse corners from a 4x or more downscaled image are off by a few px: a wide pass first
    windows = (wide, half) if scale > 2.5 else (half,)
    if scale > 2.5:
        start = _subpix(roi, coarse_local, windows, _SUBPIX_COARSE_CRITERIA)
        out = _fit(roi, start, cols, rows, radius, MAX_FIT_SHIFT)[0]
    else:
        # from a level at most 2x downscaled the fit starts at the coarse corners, within
        # about MAX_FIT_SHIFT pixels of that level from the truth
        out, far = _fit(roi, coarse_local, cols, rows, radius, MAX_FIT_SHIFT * scale)
        if np.any(far):  # further off (blurred frames): cornerSubPix first, then the fit
            start = coarse_local.copy()
            start[far] = _subpix(roi, coarse_local[far], windows, _SUBPIX_COARSE_CRITERIA)
            out[far] = _fit(roi, start, cols, rows, radius, MAX_FIT_SHIFT)[0][far]
    out += offset
    if not np.all(np.isfinite(out)):
        return None
    if smooth is not None and np.any(_off_grid(out, smooth)):
        return None  # a corner the refinement left far off the board's grid: not trusted
    return normalise_order(out, cols, rows)
