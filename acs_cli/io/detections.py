"""The checkerboard detections cache: an NPZ beside a stage's output.

Each entry is keyed by :func:`detection_key`: the image content's SHA-256, the board's
inner-corner counts and the detector version, so a changed image, another board or a new
detector never reuse a stale detection. The cache is a convenience: a missing, corrupt or
foreign cache file reads as empty (never an error), and it is written atomically, so an
interrupted run leaves the last complete snapshot.

Arrays of the NPZ (``n`` entries, ``m`` the largest corner count):

- ``schema`` = ``"acscal/detections"``, ``schema_version`` (int);
- ``keys`` (n,) str, ``names`` (n,) str (file name, informative);
- ``found`` (n,) bool, ``image_size`` (n, 2) int ``[w, h]`` pixels;
- ``n_corners`` (n,) int and ``corners`` (n, m, 2) float64 pixels (NaN-padded; all NaN
  when not found);
- ``extension`` (n,) float64, optional (caches written before it lack it): a checkerboard's
  larger-board screen score (:attr:`Detection.extension`), NaN where not measured.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from acs_cli.io.atomic import atomic_path
from acs_cli.io.trajectory import check_npz_members
from acs_cli.io.validate import MAX_MAGNITUDE

__all__ = [
    "CACHE_SCHEMA",
    "CACHE_SUFFIX",
    "Detection",
    "cache_path_for",
    "detection_key",
    "read_detections",
    "write_detections",
]

CACHE_SCHEMA = "acscal/detections"
CACHE_SCHEMA_VERSION = 1
#: ``<output stem>`` + this suffix names the cache beside an output file.
CACHE_SUFFIX = ".detections.npz"


@dataclass(frozen=True)
class Detection:
    """One image's checkerboard detection.

    Attributes
    ----------
    name : str
        The image's file name.
    found : bool
        Whether a complete board was found.
    image_size : tuple of int
        ``(width, height)`` in pixels.
    corners : ndarray, shape (cols * rows, 2) or None
        Corners row by row in pixels, None when not found.
    extension : float or None
        A checkerboard found: how much the board seems to go on beyond its corners found
        (:func:`acs_cli.core.board_hint.extension_score`), measured while the image was at
        hand, so that the check for a larger board needs not read it again; None when not
        measured.
    """

    name: str
    found: bool
    image_size: tuple[int, int]
    corners: NDArray[np.float64] | None
    extension: float | None = None


def detection_key(sha256: str, cols: int, rows: int, detector_version: str) -> str:
    """The cache key of one image's detection of a ``cols x rows`` board.

    A target of identified corners (AprilGrid, ChArUco) is keyed ``sha:<target>#<m>:version``
    instead, with ``m`` its corner count (see ``acs_cli.stages.intrinsics``).
    """
    return f"{sha256}:{cols}x{rows}:{detector_version}"


def cache_path_for(output: str | Path) -> Path:
    """The detections cache beside an output file: ``<stem>.detections.npz``."""
    out = Path(output)
    return out.with_name(out.stem + CACHE_SUFFIX)


def read_detections(path: str | Path) -> dict[str, Detection]:
    """Read a detections cache; a missing, unreadable or foreign file gives ``{}``.

    Parameters
    ----------
    path : str or Path
        The cache file.

    Returns
    -------
    dict of str to Detection
        By :func:`detection_key`.
    """
    p = Path(path)
    if not p.is_file():
        return {}
    try:
        # Open the file ourselves: np.load leaks its handle when the archive is corrupt.
        with open(p, "rb") as fh, np.load(fh, allow_pickle=False) as z:
            check_npz_members(z, p)  # a huge declared array: not a cache of ours
            if str(z["schema"]) != CACHE_SCHEMA or int(z["schema_version"]) > CACHE_SCHEMA_VERSION:
                return {}
            keys = [str(k) for k in z["keys"]]
            names = [str(k) for k in z["names"]]
            found = np.asarray(z["found"], bool)
            sizes = np.asarray(z["image_size"], np.int64).reshape(-1, 2)
            ncorn = np.asarray(z["n_corners"], np.int64)
            corners = np.asarray(z["corners"], np.float64)
            ext = (
                np.asarray(z["extension"], np.float64).ravel()
                if "extension" in z.files
                else np.full(len(keys), np.nan)
            )
    except Exception:  # corrupt archives raise many types (zipfile, zlib, ValueError, ...)
        return {}
    n = len(keys)
    if not (
        found.ndim == ncorn.ndim == 1
        and len(names) == found.shape[0] == sizes.shape[0] == ncorn.shape[0] == ext.shape[0] == n
    ):
        return {}
    if n and (corners.ndim != 3 or corners.shape[0] != n or corners.shape[2] != 2):
        return {}
    out: dict[str, Detection] = {}
    for i, key in enumerate(keys):
        c = None
        w, h = int(sizes[i, 0]), int(sizes[i, 1])
        if w <= 0 or h <= 0:
            continue
        if found[i]:
            k = int(ncorn[i])
            if k != _corner_count(key) or k > corners.shape[1]:
                continue
            c = np.array(corners[i, :k], dtype=np.float64)
            # a target of identified corners (see detection_key) has NaN rows for unseen ones
            if np.any(np.isinf(c)) or not (np.all(np.isfinite(c)) or _identified(key)):
                continue
            if np.nanmax(np.abs(c), initial=0.0) > MAX_MAGNITUDE:  # pixels: a corrupt entry
                continue
        e = float(ext[i]) if found[i] and not np.isnan(ext[i]) else None
        out[key] = Detection(names[i], bool(found[i]), (w, h), c, e)
    return out


def _identified(key: str) -> bool:
    """Whether a key's target has identified corners (label ``<target>#<m>``): its
    corners are ``(m, 2)`` with NaN rows for the corners not seen."""
    parts = key.split(":")
    return len(parts) >= 3 and "#" in parts[1]


def _corner_count(key: str) -> int:
    """``cols * rows`` of a :func:`detection_key` (``sha:COLSxROWS:version``), or the
    ``m`` of a target's label ``<target>#<m>``, or -1."""
    parts = key.split(":")
    if _identified(key):
        m = parts[1].rpartition("#")[2]
        return int(m) if m.isdigit() else -1
    cols, _, rows = parts[1].partition("x") if len(parts) >= 3 else ("", "", "")
    if not (cols.isdigit() and rows.isdigit()):
        return -1
    return int(cols) * int(rows)


#: Share of a cache's corner coordinates that are NaN (boards not found, padding, the unseen
#: corners of partly seen targets) from which :func:`write_detections` compresses the file.
#: The corners themselves hardly compress (30 boards of 476 corners: 218 KB against 244 KB,
#: 13 ms against 1 ms); the NaN of a video whose frames mostly show no board do.
COMPRESS_NAN = 0.25


def write_detections(path: str | Path, detections: Mapping[str, Detection]) -> None:
    """Write a detections cache atomically (an NPZ, compressed when at least
    :data:`COMPRESS_NAN` of its corner coordinates are NaN).

    Parameters
    ----------
    path : str or Path
        Destination file.
    detections : mapping of str to Detection
        By :func:`detection_key`.

    Raises
    ------
    InputError
        The destination cannot be written.
    """
    keys = list(detections)
    n = len(keys)
    m = max((d.corners.shape[0] for d in detections.values() if d.corners is not None), default=0)
    corners = np.full((n, m, 2), np.nan)
    ncorn = np.zeros(n, dtype=np.int64)
    for i, key in enumerate(keys):
        c = detections[key].corners
        if c is not None:
            corners[i, : c.shape[0]] = c
            ncorn[i] = c.shape[0]
    arrays = {
        "schema": np.array(CACHE_SCHEMA),
        "schema_version": np.array(CACHE_SCHEMA_VERSION, dtype=np.int64),
        "keys": np.array(keys, dtype=str) if n else np.zeros(0, dtype="<U1"),
        "names": np.array([detections[k].name for k in keys], dtype=str)
        if n
        else np.zeros(0, dtype="<U1"),
        "found": np.array([detections[k].found for k in keys], dtype=bool),
        "image_size": np.array([detections[k].image_size for k in keys], dtype=np.int64).reshape(
            n, 2
        ),
        "n_corners": ncorn,
        "corners": corners,
        "extension": np.array(
            [np.nan if (e := detections[k].extension) is None else e for k in keys], np.float64
        ),
    }
    nan = float(np.isnan(corners).mean()) if corners.size else 0.0
    save = np.savez_compressed if nan >= COMPRESS_NAN else np.savez
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            save(fh, **arrays)  # type: ignore[arg-type]
