"""Image folders: listing calibration images and reading them as greyscale arrays.

Every error is an :class:`~acs_cli.errors.InputError` naming the folder or the image.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from acs_cli.errors import InputError

__all__ = [
    "IMAGE_SUFFIXES",
    "list_images",
    "natural_key",
    "read_gray",
]

#: File suffixes (lower case) taken as images.
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")

_DIGITS = re.compile(r"(\d+)")


def natural_key(name: str) -> tuple[tuple[int, int | str], ...]:
    """Sort key that orders ``img2`` before ``img10`` (digit runs compare as numbers)."""
    parts = _DIGITS.split(name)
    return tuple((0, int(p)) if p.isdigit() else (1, p.lower()) for p in parts if p)


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


def _looks_truncated(data: bytes, suffix: str) -> str | None:
    """Why an encoded image looks cut short, or None."""
    tail = data[-4096:].rstrip(b"\x00\r\n\x1a")
    if suffix in (".jpg", ".jpeg") and data[:2] == b"\xff\xd8" and b"\xff\xd9" not in tail[-1024:]:
        return "truncated JPEG (no end-of-image marker)"
    if suffix == ".png" and data[:8] == b"\x89PNG\r\n\x1a\n" and b"IEND" not in tail[-64:]:
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
    try:
        data = p.read_bytes()
    except FileNotFoundError as exc:
        raise InputError("no such image", path=p) from exc
    except OSError as exc:
        raise InputError(f"cannot read image ({exc.strerror or exc})", path=p) from exc
    if not data:
        raise InputError("empty image file", path=p)
    sha = hashlib.sha256(data).hexdigest()
    why = _looks_truncated(data, p.suffix.lower())
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
