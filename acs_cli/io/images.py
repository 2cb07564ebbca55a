"""Image folders: listing calibration images and reading them as greyscale arrays.

Every error is an :class:`~acs_cli.errors.InputError` naming the folder or the image.
"""

from __future__ import annotations

import hashlib
import re
from decimal import Decimal
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from acs_cli.errors import InputError
from acs_cli.io.atomic import MAX_IMAGE_BYTES, read_input_bytes

__all__ = [
    "IMAGE_SUFFIXES",
    "list_images",
    "natural_key",
    "read_gray",
]

#: File suffixes (lower case) taken as images.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")

_NUMBERS = re.compile(r"(\d+(?:\.\d+)?)")


def natural_key(name: str) -> tuple[tuple[int, Decimal | str], ...]:
    """Sort key that orders ``img2`` before ``img10``: numbers compare as numbers, decimals
    included (``t_1.05.png`` before ``t_1.1.png``, as times written without fixed decimals)."""
    parts = _NUMBERS.split(name)
    return tuple((0, Decimal(p)) if p[:1].isdigit() else (1, p.lower()) for p in parts if p)


def list_images(folder: str | Path) -> list[Path]:
    """The images in a folder (not its subfolders), in natural order of file name.

    Parameters
    ----------
    folder : str or Path
        A folder of ``.png``, ``.jpg``, ``.jpeg``, ``.bmp`` or ``.tif`` files (any case).

    Returns
    -------
    list of Path

    Raises
    ------
    InputError
        The folder is missing, not a folder, empty, or holds no images.
    """
    p = Path(folder)
    if not p.exists():
        raise InputError("no such folder", path=p)
    if not p.is_dir():
        raise InputError("is not a folder of images", path=p)
    try:
        entries = [e for e in p.iterdir() if e.is_file()]
    except OSError as exc:
        raise InputError(f"cannot list folder ({exc.strerror or exc})", path=p) from exc
    if not entries:
        raise InputError("the folder is empty: expected calibration images", path=p)
    images = [e for e in entries if e.suffix.lower() in IMAGE_SUFFIXES]
    if not images:
        raise InputError(
            f"no images in the folder ({len(entries)} other file(s)); expected "
            f"{'/'.join(s.lstrip('.') for s in IMAGE_SUFFIXES)} files",
            path=p,
        )
    return sorted(images, key=lambda e: natural_key(e.name))


def _jpeg_end(data: bytes) -> int | None:
    """Where the JPEG's main image ends (just past its end-of-image marker), or None when
    the data end first: its marker segments are walked and each scan's entropy-coded data
    skipped, so that an EXIF thumbnail's marker does not count and bytes a camera appends
    after the image (phone trailers, motion photos) do not matter."""
    n, i = len(data), 2
    while i + 1 < n:
        if data[i] != 0xFF:
            return None
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
        elif marker == 0xD9:
            return i + 2
        elif 0xD0 <= marker <= 0xD7 or marker == 0x01:  # markers without a length
            i += 2
        elif i + 4 > n:
            return None
        else:
            i += 2 + int.from_bytes(data[i + 2 : i + 4], "big")
            if marker == 0xDA:  # start of scan: entropy-coded data up to the next marker
                while True:
                    i = data.find(b"\xff", i)
                    if i < 0 or i + 1 >= n:
                        return None
                    nxt = data[i + 1]
                    if nxt == 0x00 or 0xD0 <= nxt <= 0xD7 or nxt == 0xFF:
                        i += 1 if nxt == 0xFF else 2
                        continue
                    break
    return None


def _png_end(data: bytes) -> int | None:
    """Where the PNG ends (just past its IEND chunk), or None when its chunks run past the
    end of the data (bytes after IEND do not matter)."""
    n, i = len(data), 8
    while i + 8 <= n:
        end = i + 12 + int.from_bytes(data[i : i + 4], "big")
        if end > n:
            return None
        if data[i + 4 : i + 8] == b"IEND":
            return end
        i = end
    return None


def _looks_truncated(data: bytes) -> str | None:
    """Why an encoded image looks cut short, or None."""
    if data[:2] == b"\xff\xd8" and _jpeg_end(data) is None:
        return "truncated JPEG (no end-of-image marker)"
    if data[:8] == b"\x89PNG\r\n\x1a\n" and _png_end(data) is None:
        return "truncated PNG (no IEND chunk)"
    return None


def read_gray(path: str | Path) -> tuple[NDArray[np.uint8], str]:
    """Read an image as 8-bit greyscale, with the SHA-256 of its bytes.

    Parameters
    ----------
    path : str or Path
        An image file.

    Returns
    -------
    image : ndarray, shape (h, w), uint8
    sha256 : str
        Hex digest of the file's content.

    Raises
    ------
    InputError
        Unreadable, empty, truncated (a JPEG without its end marker, a PNG without its IEND
        chunk) or undecodable file.
    """
    p = Path(path)
    data = read_input_bytes(p, "an image", MAX_IMAGE_BYTES)
    if not data:
        raise InputError("empty image file", path=p)
    sha = hashlib.sha256(data).hexdigest()
    why = _looks_truncated(data)
    if why is not None:
        raise InputError(f"corrupt image: {why}", path=p)
    try:
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)
    except cv2.error:
        img = None
    if img is None or img.size == 0:
        raise InputError("corrupt image: cannot decode it (not an image or damaged)", path=p)
    if img.dtype != np.uint8:  # 16-bit PNG/TIFF
        f = img.astype(float)
        lo, hi = float(f.min()), float(f.max())
        scaled = (f - lo) * (255.0 / (hi - lo)) if hi > lo else np.zeros(f.shape)
        img = np.clip(np.round(scaled), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(img), sha
