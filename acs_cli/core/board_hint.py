"""Which checkerboard size the images show, when the given one looks wrong (issue 13).

The usual mistake is counting squares instead of inner corners (``--board 10x7`` for a
board of 9x6 inner corners), or an off-by-one in one direction. :func:`board_size_hint`
tries sizes on a few images with OpenCV's quick check on a downscaled copy and names the
one found in the most of them: the nearby sizes (:func:`nearby_board_sizes`) where the
given size was not found, and the larger ones (:func:`larger_board_sizes`) where it was:
OpenCV finds an 8x6 board inside a 9x6 one, whose origin then jumps from image to image.
Where the given size was found, :func:`board_extension_scores` first asks the image itself:
does the checker pattern go on beyond the corners found? A look at a few dozen pixels, where
a search for each larger size takes a tenth of a second per image; only where it cannot rule
a larger board out is it searched for.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from acs_cli.core.checkerboard import downscaled

__all__ = [
    "HINT_WIDTH",
    "board_extension_scores",
    "board_size_hint",
    "extension_score",
    "larger_board_sizes",
    "nearby_board_sizes",
]

#: Images are tried at most this wide (pixels): the quick check needs no detail.
HINT_WIDTH = 800
_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK


def nearby_board_sizes(cols: int, rows: int) -> list[tuple[int, int]]:
    """Sizes (inner corners) a user who gave ``cols x rows`` may have meant, likeliest first:
    squares counted instead of corners, then one more or fewer in one or both directions.
    Sizes below 3 corners in a direction, and the given size, are left out."""
    steps = [(-1, -1), (1, 1), (-1, 0), (0, -1), (1, 0), (0, 1), (-1, 1), (1, -1)]
    out: list[tuple[int, int]] = []
    for dc, dr in steps:
        c, r = cols + dc, rows + dr
        if c >= 3 and r >= 3 and (c, r) != (cols, rows) and (c, r) not in out:
            out.append((c, r))
    return out


def larger_board_sizes(cols: int, rows: int) -> list[tuple[int, int]]:
    """Boards of which a ``cols x rows`` board can be a part: one more corner in one or both
    directions."""
    return [(cols + 1, rows + 1), (cols + 1, rows), (cols, rows + 1)]


def board_size_hint(
    images: Sequence[NDArray[np.uint8]], sizes: Sequence[tuple[int, int]]
) -> tuple[tuple[int, int], int] | None:
    """The board size of ``sizes`` found in the most of ``images``, and in how many.

    Parameters
    ----------
    images : sequence of ndarray, shape (h, w), uint8
        Greyscale images (a few suffice).
    sizes : sequence of (cols, rows)
        Inner-corner counts to try, likeliest first (ties go to the first).

    Returns
    -------
    ((cols, rows), count) or None
        None when no size is found in any image.
    """
    small = [downscaled(np.asarray(g, dtype=np.uint8), HINT_WIDTH) for g in images]
    best: tuple[tuple[int, int], int] | None = None
    for size in sizes:
        count = sum(bool(cv2.findChessboardCorners(g, size, flags=_FLAGS)[0]) for g in small)
        if count and (best is None or count > best[1]):
            best = (size, count)
            if count == len(small):
                break
    return best


#: Largest continuation score (:func:`board_extension_scores`) that rules a larger board
#: out without a search. On OpenCV's 26 photographs of a 9x6 board, the sides of the board
#: found whole score at most 0.23 (lens blur, lighting, extrapolation), and the missing side
#: of an 8x6, 7x6 or 9x5 part of it at least 0.33: a screen, the search still decides above
#: it. Rendered boards score about 0.
EXTENSION_SCREEN = 0.25
#: Where in a square its brightness is sampled (bilinear coordinates in its four corners):
#: its centre and four points away from its edges, so that blur and an extrapolated corner
#: a little off still land inside it.
_SPOTS = np.array([[0.5, 0.5], [0.3, 0.3], [0.7, 0.3], [0.3, 0.7], [0.7, 0.7]])


def _extended(grid: NDArray[np.float64]) -> NDArray[np.float64]:
    """The corner grid ``(rows, cols, 2)`` with two more corners on each side of each row and
    column ``(rows + 4, cols + 4, 2)``, extrapolated along the lattice (quadratically where
    three corners allow: a lens's distortion bends the rows)."""

    def grow(g: NDArray[np.float64]) -> NDArray[np.float64]:  # along axis 1, both ends
        for _ in range(2):
            if g.shape[1] >= 3:
                right = 3 * g[:, -1] - 3 * g[:, -2] + g[:, -3]
                left = 3 * g[:, 0] - 3 * g[:, 1] + g[:, 2]
            else:
                right, left = 2 * g[:, -1] - g[:, -2], 2 * g[:, 0] - g[:, 1]
            g = np.concatenate([left[:, None], g, right[:, None]], axis=1)
        return g

    wide = grow(grid)
    return np.swapaxes(grow(np.swapaxes(wide, 0, 1)), 0, 1)


def _square_brightness(
    grey: NDArray[np.uint8], ext: NDArray[np.float64], a: np.ndarray, b: np.ndarray
) -> NDArray[np.float64]:
    """Mean brightness ``(k,)`` of the squares ``(a, b)`` (the square between corners ``a,
    a + 1`` of a row and ``b, b + 1`` of a column; ``-2 <= a < cols + 1``) of the extended
    grid ``ext`` (:func:`_extended`); NaN where a sample falls outside the image."""
    i, j = a + 2, b + 2
    p00, p10, p01, p11 = ext[j, i], ext[j, i + 1], ext[j + 1, i], ext[j + 1, i + 1]
    u, v = _SPOTS[:, 0][None, :, None], _SPOTS[:, 1][None, :, None]
    pix = (
        (1 - u) * (1 - v) * p00[:, None]
        + u * (1 - v) * p10[:, None]
        + (1 - u) * v * p01[:, None]
        + u * v * p11[:, None]
    ).reshape(-1, 2)
    h, w = grey.shape
    x, y = np.rint(pix[:, 0]), np.rint(pix[:, 1])
    inside = np.isfinite(x) & np.isfinite(y) & (x >= 0) & (x < w) & (y >= 0) & (y < h)
    vals = np.full(x.size, np.nan)
    vals[inside] = grey[y[inside].astype(int), x[inside].astype(int)]
    vals = vals.reshape(a.size, _SPOTS.shape[0])
    out = np.full(a.size, np.nan)
    whole = np.all(np.isfinite(vals), axis=1)
    out[whole] = vals[whole].mean(axis=1)
    return out


def board_extension_scores(
    grey: NDArray[np.uint8], corners: NDArray[np.float64], cols: int, rows: int
) -> NDArray[np.float64]:
    """How much the checkerboard seems to go on beyond the ``cols x rows`` inner corners
    found, on each side: ``(left, right, top, bottom)``, NaN where the image cannot tell.

    The squares around the corners found (``cols + 1`` by ``rows + 1``) set the board's
    alternation and contrast. Each side's score is the contrast of the column (row) of squares
    just outside them, its corners extrapolated along the lattice, in the board's alternation,
    as a share of the board's own: about 1 where the board goes on, about 0 for a margin or a
    plain background, negative against the alternation.

    Parameters
    ----------
    grey : ndarray, shape (h, w), uint8
        The image.
    corners : ndarray, shape (cols * rows, 2)
        The inner corners found in it (pixels), in OpenCV's order: ``rows`` rows of ``cols``.
    cols, rows : int
        The board size given (inner corners).

    Returns
    -------
    ndarray, shape (4,)
    """
    out = np.full(4, np.nan)
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] != cols * rows or cols < 2 or rows < 2:
        return out
    ext = _extended(pts.reshape(rows, cols, 2))
    # the board's own squares: a in -1 .. cols - 1, b in -1 .. rows - 1
    a, b = (m.ravel() for m in np.meshgrid(np.arange(-1, cols), np.arange(-1, rows)))
    v = _square_brightness(grey, ext, a, b)
    ok = np.isfinite(v)
    if ok.sum() < 4:
        return out
    mid = float(np.mean(v[ok]))
    # signed: which parity is dark
    contrast = float(np.mean((v[ok] - mid) * np.where((a[ok] + b[ok]) % 2 == 0, 1.0, -1.0)))
    if abs(contrast) < 1.0:  # grey levels: no checker pattern to speak of
        return out
    bs, as_ = np.arange(-1, rows), np.arange(-1, cols)
    sides = [
        (np.full(bs.size, -2), bs),
        (np.full(bs.size, cols), bs),
        (as_, np.full(as_.size, -2)),
        (as_, np.full(as_.size, rows)),
    ]
    for k, (sa, sb) in enumerate(sides):
        vals = _square_brightness(grey, ext, sa, sb)
        good = np.isfinite(vals)
        if good.sum() < max(2, sa.size // 2):
            continue
        par = np.where((sa[good] + sb[good]) % 2 == 0, 1.0, -1.0)
        # about the side's own mean: an odd number of squares of a plain margin scores 0
        out[k] = float(np.mean((vals[good] - np.mean(vals[good])) * par)) / contrast
    return out


def extension_score(
    grey: NDArray[np.uint8], corners: NDArray[np.float64], cols: int, rows: int
) -> float:
    """The larger-board screen's score of one image: the highest of
    :func:`board_extension_scores` over the four sides, a side the image cannot tell
    counting 0 (a board mostly out of view there is not in view whole), and ``inf`` when
    no side can be told at all (no checker pattern measured: only a search can tell).

    Below :data:`EXTENSION_SCREEN`, the image rules out a board larger than
    ``cols x rows``.
    """
    scores = board_extension_scores(grey, corners, cols, rows)
    if np.all(np.isnan(scores)):
        return math.inf
    return float(np.max(np.nan_to_num(scores, nan=0.0)))
