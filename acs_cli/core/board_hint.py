"""Which checkerboard size the images show, when the given one looks wrong (issue 13).

The usual mistake is counting squares instead of inner corners (``--board 10x7`` for a
board of 9x6 inner corners), or an off-by-one in one direction. :func:`board_size_hint`
tries sizes on a few images with OpenCV's quick check on a downscaled copy and names the
one found in the most of them: the nearby sizes (:func:`nearby_board_sizes`) where the
given size was not found, and the larger ones (:func:`larger_board_sizes`) where it was:
OpenCV finds an 8x6 board inside a 9x6 one, whose origin then jumps from image to image.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from acs_cli.core.checkerboard import downscaled

__all__ = ["HINT_WIDTH", "board_size_hint", "larger_board_sizes", "nearby_board_sizes"]

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
