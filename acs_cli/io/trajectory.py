"""Camera trajectories: TUM, KITTI, COLMAP text models and acscal NPZ poses.

Every reader returns a :class:`Trajectory` holding ``T_world_cam`` (the camera's pose in its
world frame: ``p_world = T_world_cam @ p_cam``), whatever the file stores. Every error the
file can cause is an :class:`~acs_cli.errors.InputError` naming the file and, for text
formats, the line.
"""

from __future__ import annotations

import io
import json
import operator
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from itertools import repeat
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.atomic import (
    MAX_NPZ_BYTES,
    MAX_NPZ_MEMBER_BYTES,
    MAX_TEXT_BYTES,
    atomic_path,
    atomic_write_text,
    read_input_bytes,
)
from acs_cli.io.images import natural_key
from acs_cli.io.timestamps import image_times
from acs_cli.io.validate import check_magnitude

__all__ = [
    "FORMATS",
    "FRAME_NUMBERS_NOTE",
    "KITTI_ORTHONORMAL_TOL",
    "NPZ_SCHEMA",
    "NPZ_SCHEMA_VERSION",
    "QUAT_NORM_TOL",
    "TIME_UNITS",
    "Trajectory",
    "check_npz_members",
    "parse_trajectory",
    "read_input",
    "read_trajectory",
    "write_kitti",
    "write_npz_poses",
    "write_tum",
]

FloatArray = se3.FloatArray

#: Formats :func:`read_trajectory` accepts.
FORMATS = ("auto", "tum", "kitti", "colmap", "npz")
#: Units of a trajectory's times: seconds, or frame numbers (see :mod:`acs_cli.io.timestamps`).
TIME_UNITS = ("s", "frame")
#: How a TUM file's comment says that its times are frame numbers (read back as such).
FRAME_NUMBERS_NOTE = "times are frame numbers"
#: Largest accepted ``|norm(q) - 1|`` of a quaternion in a TUM or COLMAP file.
QUAT_NORM_TOL = 1e-3
#: Largest accepted ``|R^T R - I|`` entry of a rotation block in a KITTI or NPZ file.
KITTI_ORTHONORMAL_TOL = 1e-4
#: ``schema`` of the NPZ the ``acscal poses`` stage writes.
NPZ_SCHEMA = "acscal/poses"
#: Newest NPZ schema version this code reads and the one it writes.
NPZ_SCHEMA_VERSION = 1

_NPZ_RESERVED = (
    "schema",
    "schema_version",
    "T_world_cam",
    "timestamps",
    "has_timestamps",
    "image_names",
    "header_json",
    "timestamps_ns",
    "time_unit",
)


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A camera trajectory: one pose per frame.

    Attributes
    ----------
    timestamps : ndarray, shape (n,)
        Strictly increasing times in seconds, or frame indices when ``has_timestamps`` is
        False.
    T_world_cam : ndarray, shape (n, 4, 4)
        Pose of the camera in the trajectory's world frame (maps camera points to world).
        Units of the translation are the trajectory's own (metres or an unknown scale).
    source : str
        The file the trajectory was read from (used in messages).
    format : str
        ``"tum"``, ``"kitti"``, ``"colmap"``, ``"npz"`` or a caller's label.
    has_timestamps : bool
        Whether ``timestamps`` are times (pair by timestamp) or indices (pair by index).
    names : tuple of str
        Image names, one per pose, when known; else empty.
    timestamps_ns : ndarray of int64, shape (n,), or None
        The same times as exact integer nanoseconds, when the source gave them (nanosecond
        image names, a TUM file's digits); TUM files are written from them.
    time_unit : str
        ``"s"`` (seconds) or ``"frame"`` (frame numbers: pairable with other frame numbers,
        but not times; see :mod:`acs_cli.io.timestamps`).

    Raises
    ------
    InputError
        On construction, if shapes disagree, a value is not finite, a rotation block is not
        orthonormal (``se3.ORTHONORMAL_TOL``) or the timestamps do not increase. The message
        names ``source``.
    """

    timestamps: FloatArray
    T_world_cam: FloatArray
    source: str
    format: str
    has_timestamps: bool
    names: tuple[str, ...] = ()
    timestamps_ns: NDArray[np.int64] | None = None
    time_unit: str = "s"

    def __post_init__(self) -> None:
        src = self.source
        try:
            t = np.asarray(self.timestamps, dtype=float)
            T = np.asarray(self.T_world_cam, dtype=float)
        except (TypeError, ValueError) as exc:
            raise InputError(f"poses or timestamps are not numeric ({exc})", path=src) from exc
        if T.ndim != 3 or T.shape[1:] != (4, 4):
            raise InputError(f"T_world_cam must have shape (n, 4, 4), got {T.shape}", path=src)
        n = T.shape[0]
        if n == 0:
            raise InputError("the trajectory has no poses", path=src)
        if t.shape != (n,):
            raise InputError(
                f"expected {n} timestamps (one per pose), got shape {t.shape}", path=src
            )
        if not np.all(np.isfinite(t)):
            raise InputError("timestamps contain NaN or inf", path=src)
        check_magnitude(t, "timestamps", src)  # seconds (1e10 s is the year 2286)
        with np.errstate(all="ignore"):
            bad = np.flatnonzero(np.diff(t) <= 0)
        if bad.size:
            i = int(bad[0]) + 1
            raise InputError(
                f"timestamps must increase: timestamps[{i}] = {float(t[i])!r} follows "
                f"{float(t[i - 1])!r}",
                path=src,
            )
        if self.names and len(self.names) != n:
            raise InputError(f"expected {n} image names, got {len(self.names)}", path=src)
        try:
            se3.check_transforms(T, name="T_world_cam")
        except InputError as exc:
            raise InputError(exc.message, path=src) from exc
        check_magnitude(T[:, :3, 3], "translations", src, extent=True)
        object.__setattr__(self, "timestamps", t)
        object.__setattr__(self, "T_world_cam", T)
        object.__setattr__(self, "names", tuple(str(s) for s in self.names))
        object.__setattr__(self, "has_timestamps", bool(self.has_timestamps))
        if self.time_unit not in TIME_UNITS:
            raise InputError(
                f"time unit {self.time_unit!r} is not one of {', '.join(TIME_UNITS)}", path=src
            )
        if self.timestamps_ns is not None:
            ns = np.asarray(self.timestamps_ns)
            if ns.shape != (n,) or ns.dtype.kind not in "iu":
                raise InputError(
                    f"timestamps_ns must be {n} integers, got {ns.dtype} {ns.shape}", path=src
                )
            ns = ns.astype(np.int64)
            whole, frac = np.divmod(ns, 10**9)
            if np.any(np.abs(whole - t + frac / 1e9) > 1e-6 + 1e-15 * np.abs(t)):
                raise InputError("timestamps_ns disagree with timestamps (seconds)", path=src)
            object.__setattr__(self, "timestamps_ns", ns)

    def __len__(self) -> int:
        return int(self.T_world_cam.shape[0])

    def select(self, idx: ArrayLike) -> Trajectory:
        """The sub-trajectory at increasing indices ``idx`` (shape ``(m,)``, ``m >= 1``)."""
        ii = np.asarray(idx, dtype=np.intp)
        names = tuple(self.names[i] for i in ii) if self.names else ()
        return Trajectory(
            timestamps=self.timestamps[ii],
            T_world_cam=self.T_world_cam[ii],
            source=self.source,
            format=self.format,
            has_timestamps=self.has_timestamps,
            names=names,
            timestamps_ns=None if self.timestamps_ns is None else self.timestamps_ns[ii],
            time_unit=self.time_unit,
        )


# --------------------------------------------------------------------------------------
# text helpers


def _decode_text(data: bytes, path: Path) -> str:
    """A file's text (UTF-8, optional BOM) from its bytes; every failure is an InputError."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise InputError("not a UTF-8 text file", path=path, line=line) from exc


def _data_lines(text: str) -> tuple[list[str], list[int]]:
    """Non-blank lines not starting with ``#`` and their 1-based line numbers."""
    stripped = list(map(str.strip, text.split("\n")))
    numbers = [k for k, s in enumerate(stripped, start=1) if s and s[0] != "#"]
    return [stripped[k - 1] for k in numbers], numbers


def _first_data_line(text: str) -> tuple[str, int] | None:
    """The first line :func:`_data_lines` keeps and its line number (None: no such line),
    without splitting the whole text."""
    start, number = 0, 1
    while True:
        end = text.find("\n", start)
        s = (text[start:] if end < 0 else text[start:end]).strip()
        if s and s[0] != "#":
            return s, number
        if end < 0:
            return None
        start, number = end + 1, number + 1


def _parse_table(
    lines: list[str], numbers: list[int], ncols: int, layout: str, path: Path
) -> FloatArray:
    """Parse whitespace-separated numbers, ``ncols`` a line, into ``(n, ncols)`` floats.

    Raises an InputError naming the first line with a wrong column count, a token that is
    not a number, or a NaN/inf.
    """
    counts = np.fromiter(map(len, map(str.split, lines)), dtype=np.intp, count=len(lines))
    wrong = np.flatnonzero(counts != ncols)
    if wrong.size:
        k = int(wrong[0])
        raise InputError(
            f"expected {ncols} numbers ({layout}), got {counts[k]}", path=path, line=numbers[k]
        )
    table = _loadtxt(lines, ncols)
    if table is None:
        table = _floats_one_by_one(lines, numbers, ncols, path)
    bad = np.flatnonzero(~np.isfinite(table).all(axis=1))
    if bad.size:
        raise InputError("contains NaN or inf", path=path, line=numbers[int(bad[0])])
    return table


def _floats_one_by_one(lines: list[str], numbers: list[int], ncols: int, path: Path) -> FloatArray:
    """``(n, ncols)`` floats of ``lines`` by ``float``, a token at a time; an InputError
    names the line of the first token that is not a number."""
    rows = [s.split() for s in lines]
    try:
        flat = np.array([float(tok) for row in rows for tok in row], dtype=float)
    except ValueError:
        for row, line in zip(rows, numbers, strict=True):
            for tok in row:
                try:
                    float(tok)
                except ValueError:
                    shown = tok if len(tok) <= 40 else tok[:37] + "..."
                    raise InputError(f"not a number: {shown!r}", path=path, line=line) from None
        raise  # pragma: no cover - the loop above always finds the bad token
    return flat.reshape(len(rows), ncols)


def _loadtxt(lines: list[str], ncols: int) -> FloatArray | None:
    """``(n, ncols)`` floats of ``lines`` (stripped, ``ncols`` tokens each) by NumPy's text
    reader, several times faster than ``float`` a token on a long file; None when it refuses
    them (it reads ASCII only, no ``1_000``: ``float`` may still read them, and the caller
    falls back to it, for its messages too).

    Where it reads every token, it reads each as ``float`` does (both parse with CPython's
    ``PyOS_string_to_double``) and splits the lines at the same (Unicode) whitespace as
    ``str.split``; a line it would split otherwise (at a carriage return) changes the shape.
    """
    if not lines:
        return None
    try:
        table = np.loadtxt(lines, dtype=float, comments=None, ndmin=2)
    except ValueError:
        return None
    return table if table.shape == (len(lines), ncols) else None


def _check_quaternions(q: FloatArray, numbers: list[int], path: Path) -> FloatArray:
    """Normalised ``(n, 4)`` quaternions; InputError naming a line whose norm is off."""
    with np.errstate(all="ignore"):
        norm = np.sqrt(np.sum(q * q, axis=1))
        bad = np.flatnonzero(~(np.abs(norm - 1.0) <= QUAT_NORM_TOL))
    if bad.size:
        k = int(bad[0])
        raise InputError(
            f"quaternion norm is {norm[k]:.6g}, not 1 (tolerance {QUAT_NORM_TOL:g})",
            path=path,
            line=numbers[k],
        )
    return q / norm[:, None]


def _check_increasing(t: FloatArray, numbers: list[int], path: Path) -> None:
    with np.errstate(all="ignore"):
        bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        what = "repeats" if t[k] == t[k - 1] else "is before"
        raise InputError(
            f"timestamp {float(t[k])!r} {what} the previous one ({float(t[k - 1])!r} on line "
            f"{numbers[k - 1]}); timestamps must increase",
            path=path,
            line=numbers[k],
        )


def _check_rotation_blocks(
    R: FloatArray, numbers: list[int] | None, path: Path, what: str
) -> FloatArray:
    """Check ``(n, 3, 3)`` blocks are rotations within KITTI_ORTHONORMAL_TOL; re-orthonormalise."""
    with np.errstate(all="ignore"):
        err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2))
        det = np.linalg.det(R)
        bad = np.flatnonzero(~(err <= KITTI_ORTHONORMAL_TOL) | ~(det > 0))
    if bad.size:
        k = int(bad[0])
        problem = (
            "is a reflection (det < 0)"
            if det[k] <= 0
            else f"is not orthonormal (|R^T R - I| = {err[k]:.2e} > {KITTI_ORTHONORMAL_TOL:g})"
        )
        if numbers is None:
            raise InputError(f"{what}[{k}] rotation block {problem}", path=path)
        raise InputError(f"the rotation block {problem}", path=path, line=numbers[k])
    R_fixed, _ = se3.project_to_rotation(R)
    return np.asarray(R_fixed, dtype=float)


# --------------------------------------------------------------------------------------
# TUM


def _parse_tum(text: str, p: Path) -> Trajectory:
    """A TUM trajectory: ``timestamp tx ty tz qx qy qz qw`` per line, ``T_world_cam``.

    Lines starting with ``#`` and blank lines are skipped; quaternions ``(x, y, z, w)`` are
    normalised (refused off 1 by more than :data:`QUAT_NORM_TOL`), timestamps must increase.
    Times are seconds, or frame numbers (``time_unit="frame"``) when a comment line says
    :data:`FRAME_NUMBERS_NOTE` (as acscal writes them); ``timestamps_ns`` is set exactly
    when every time is a plain decimal of at most 9 places.
    """
    lines, numbers = _data_lines(text)
    if not lines:
        raise InputError("contains no poses (empty TUM file)", path=p)
    table = _parse_table(lines, numbers, 8, "timestamp tx ty tz qx qy qz qw", p)
    t = table[:, 0].copy()
    _check_increasing(t, numbers, p)
    q = _check_quaternions(table[:, 4:8], numbers, p)
    R = se3.matrix_from_checked_quat_xyzw(q)
    T = se3.transforms_from_rt(R, table[:, 1:4]).reshape(-1, 4, 4)
    return Trajectory(
        t,
        T,
        source=str(p),
        format="tum",
        has_timestamps=True,
        timestamps_ns=_exact_nanoseconds([s.split(None, 1)[0] for s in lines]),
        # the plain search first: the pattern's scan of a long file is slow
        time_unit="frame" if FRAME_NUMBERS_NOTE in text and _FRAME_NOTE.search(text) else "s",
    )


_FRAME_NOTE = re.compile(r"^#\s*" + FRAME_NUMBERS_NOTE, re.MULTILINE)
_PLAIN_DECIMAL = re.compile(r"^\d+(?:\.\d{0,9})?$")
#: Tokens (joined by line breaks) of exactly 9 decimals each, as :func:`write_tum` writes.
_NINE_DECIMALS = re.compile(r"(?:\d+\.\d{9}\n)*\d+\.\d{9}")


def _exact_nanoseconds(tokens: list[str]) -> NDArray[np.int64] | None:
    """Integer nanoseconds of plain decimal seconds (at most 9 decimals, below ~292 years
    of int64), exactly; None when any token is not of that form (e.g. ``1.5e9``)."""
    # the per-token work in C (a long file has a token a line): one match of the tokens
    # joined (a token holds no line break), ``map``s
    joined = "\n".join(tokens)
    if _NINE_DECIMALS.fullmatch(joined):  # as write_tum writes them: digits = nanoseconds
        out = list(map(int, joined.replace(".", "").split("\n")))
    elif all(map(_PLAIN_DECIMAL.match, tokens)):  # digits times 10 ** (9 - decimals)
        n = len(tokens)
        dots = np.fromiter(map(str.find, tokens, repeat(".")), dtype=np.intp, count=n)
        sizes = np.fromiter(map(len, tokens), dtype=np.intp, count=n)
        shifts = (9 - np.where(dots < 0, 0, sizes - dots - 1)).tolist()
        digits = map(int, joined.replace(".", "").split("\n"))
        out = list(map(operator.mul, digits, map(pow, repeat(10), shifts)))
    else:
        return None
    if max(out) >= 2**63:
        return None
    return np.array(out, dtype=np.int64)


def _check_poses(T_world_cam: ArrayLike, n_expected: int | None = None) -> FloatArray:
    T = se3.check_transforms(T_world_cam, name="T_world_cam")
    if n_expected is not None and T.shape[0] != n_expected:
        raise InputError(f"got {n_expected} timestamps but {T.shape[0]} poses")
    return T


def write_tum(
    path: str | Path,
    timestamps: ArrayLike,
    T_world_cam: ArrayLike,
    *,
    timestamps_ns: ArrayLike | None = None,
    note: str | None = None,
) -> None:
    """Write a TUM trajectory atomically.

    Parameters
    ----------
    path : str or Path
        Destination file.
    timestamps : array_like, shape (n,)
        Seconds; written with ``%.9f``.
    timestamps_ns : array_like of int, shape (n,), optional
        The same times in integer nanoseconds: written from them, digit for digit.
    note : str, optional
        A comment line written under the header (e.g. that the times are frame numbers).
    T_world_cam : array_like, shape (n, 4, 4)
        Camera poses in the world frame. Written as ``tx ty tz qx qy qz qw`` with 15
        significant digits and ``qw >= 0``, so :func:`read_trajectory` gives them back to ~1e-12.

    Raises
    ------
    InputError
        Wrong shapes, non-finite values, non-rotations, or an unwritable destination.
    """
    t = np.asarray(timestamps, dtype=float).reshape(-1)
    T = _check_poses(T_world_cam, t.shape[0])
    if not np.all(np.isfinite(t)):
        raise InputError("timestamps contain NaN or inf", path=path)
    q = se3.quat_xyzw_from_matrix(T[:, :3, :3]).reshape(-1, 4)
    if timestamps_ns is None:
        stamps: FloatArray | list[str] = t
        row = "%.9f"
    else:
        ns = np.asarray(timestamps_ns, dtype=np.int64).reshape(-1)
        if ns.shape != t.shape:
            raise InputError(f"{ns.size} nanosecond timestamps for {t.size} poses", path=path)
        stamps = [
            f"{'-' if v < 0 else ''}{abs(v) // 10**9}.{abs(v) % 10**9:09d}" for v in ns.tolist()
        ]
        row = "%s"
    row += " %.15g" * 7 + "\n"
    head = "# timestamp tx ty tz qx qy qz qw\n"
    if note is not None:
        head += "# " + note.replace("\n", "\n# ") + "\n"
    values = np.column_stack([T[:, :3, 3], q])
    # rows formatted a block at a time by one %-format of the block's cells (a loop per row
    # costs several times more on a long trajectory; the block bounds the cells' memory)
    parts = [head]
    for a in range(0, t.size, _TUM_BLOCK):
        b = min(a + _TUM_BLOCK, t.size)
        cells = np.empty((b - a, 8), dtype=object)
        cells[:, 0] = stamps[a:b]
        cells[:, 1:] = values[a:b]
        parts.append((row * (b - a)) % tuple(cells.ravel().tolist()))
    atomic_write_text(path, "".join(parts))


#: Rows :func:`write_tum` formats at a time.
_TUM_BLOCK = 4096


# --------------------------------------------------------------------------------------
# KITTI


def _parse_kitti(text: str, p: Path) -> Trajectory:
    """A KITTI trajectory: 12 numbers a line, the row-major top 3x4 of ``T_world_cam``.

    Timestamps are the frame indices (``has_timestamps=False``); rotation blocks must be
    orthonormal within :data:`KITTI_ORTHONORMAL_TOL` and are re-orthonormalised.
    """
    lines, numbers = _data_lines(text)
    if not lines:
        raise InputError("contains no poses (empty KITTI file)", path=p)
    table = _parse_table(lines, numbers, 12, "the row-major top 3x4 of T_world_cam", p)
    M = table.reshape(-1, 3, 4)
    R = _check_rotation_blocks(M[:, :, :3], numbers, p, "T_world_cam")
    T = se3.transforms_from_rt(R, M[:, :, 3]).reshape(-1, 4, 4)
    t = np.arange(T.shape[0], dtype=float)
    return Trajectory(t, T, source=str(p), format="kitti", has_timestamps=False)


def write_kitti(path: str | Path, T_world_cam: ArrayLike) -> None:
    """Write a KITTI trajectory atomically (12 numbers a line, 15 significant digits).

    Parameters
    ----------
    path : str or Path
        Destination file.
    T_world_cam : array_like, shape (n, 4, 4)
        Camera poses in the world frame.
    """
    T = _check_poses(T_world_cam)
    buf = io.StringIO()
    np.savetxt(buf, T[:, :3, :].reshape(-1, 12), fmt="%.15g")
    atomic_write_text(path, buf.getvalue())


# --------------------------------------------------------------------------------------
# COLMAP


def _is_float(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def _colmap_file(path: Path) -> Path:
    if path.is_dir():
        f = path / "images.txt"
        if not f.is_file():
            hint = (
                " (found images.bin: convert the binary model with "
                "`colmap model_converter --output_type TXT`)"
                if (path / "images.bin").exists()
                else ""
            )
            raise InputError(f"no images.txt in this folder{hint}", path=path)
        return f
    return path


def _parse_colmap(text: str, p: Path) -> Trajectory:
    """Camera poses of a COLMAP text model's ``images.txt``.

    Each image takes two lines: ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` and its
    POINTS2D line (``X Y POINT3D_ID`` triples, possibly empty). The stored pose is
    ``cam_from_world`` (``T_cam_world``); it is inverted to ``T_world_cam``. Poses come in
    natural order of image name (``img2`` before ``img10``), ``names`` set; if every name's
    stem holds a number and these increase, they are the timestamps, else the indices.
    """
    entries: list[tuple[str, int]] = []
    values: list[list[float]] = []
    raw_lines = text.split("\n")
    body = [
        (k, s.strip()) for k, s in enumerate(raw_lines, start=1) if not s.lstrip().startswith("#")
    ]
    i = 0
    while i < len(body):
        line_no, s = body[i]
        if not s:
            i += 1
            continue
        fields = s.split(maxsplit=9)
        if len(fields) < 10:
            raise InputError(
                "expected an image line: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME "
                f"(got {len(fields)} fields)",
                path=p,
                line=line_no,
            )
        try:
            int(fields[0]), int(fields[8])
            nums = [float(x) for x in fields[1:8]]
        except ValueError:
            raise InputError(
                "expected an image line: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME "
                "(IDs integers, pose numbers)",
                path=p,
                line=line_no,
            ) from None
        entries.append((fields[9].strip(), line_no))
        values.append(nums)
        if i + 1 < len(body):
            pts_line, pts = body[i + 1]
            # triples of numbers: an image line of a file without POINTS2D lines can split
            # into triples (a name of three words), and must not be taken for one
            if len(pts.split()) % 3 or not all(_is_float(tok) for tok in pts.split()):
                raise InputError(
                    "expected the POINTS2D line (X Y POINT3D_ID triples) of the image on "
                    f"line {line_no}",
                    path=p,
                    line=pts_line,
                )
        i += 2
    if not entries:
        raise InputError("contains no images (empty COLMAP images.txt)", path=p)
    numbers = [ln for _, ln in entries]
    table = np.asarray(values, dtype=float)
    bad = np.flatnonzero(~np.isfinite(table).all(axis=1))
    if bad.size:
        raise InputError("contains NaN or inf", path=p, line=numbers[int(bad[0])])
    seen: dict[str, int] = {}
    for name, ln in entries:
        if name in seen:
            raise InputError(
                f"image name {name!r} repeats (first on line {seen[name]})", path=p, line=ln
            )
        seen[name] = ln
    q_wxyz = _check_quaternions(table[:, 0:4], numbers, p)
    R_cam_world = se3.matrix_from_checked_quat_xyzw(q_wxyz[:, [1, 2, 3, 0]])
    T_cam_world = se3.transforms_from_rt(R_cam_world, table[:, 4:7]).reshape(-1, 4, 4)
    with np.errstate(all="ignore"):
        T_world_cam = se3.invert_transforms(T_cam_world)
    if not np.all(np.isfinite(T_world_cam)):
        raise InputError("a translation is too large to invert", path=p)

    names = [name for name, _ in entries]
    order = sorted(range(len(names)), key=lambda k: (natural_key(names[k]), names[k]))
    names_sorted = tuple(names[k] for k in order)
    T_sorted = T_world_cam[order]
    base = [PurePosixPath(name.replace("\\", "/")).name for name in names_sorted]
    times = image_times(base, base)
    return Trajectory(
        times.seconds,
        T_sorted,
        source=str(p),
        format="colmap",
        has_timestamps=times.has_timestamps,
        names=names_sorted,
        timestamps_ns=times.nanoseconds,
        time_unit=times.unit,
    )


# --------------------------------------------------------------------------------------
# NPZ


def check_npz_members(z: np.lib.npyio.NpzFile, path: Path) -> None:
    """Refuse an archive whose arrays declare more than :data:`MAX_NPZ_MEMBER_BYTES` each
    (read from each ``.npy`` header, before any array is loaded)."""
    archive = z.zip
    if archive is None:  # pragma: no cover - an open NpzFile holds its archive
        return
    for info in archive.infolist():
        with archive.open(info) as fp:
            version = np.lib.format.read_magic(fp)
            if version == (1, 0):
                shape, _, dtype = np.lib.format.read_array_header_1_0(fp)
            else:
                shape, _, dtype = np.lib.format.read_array_header_2_0(fp)
        size = int(np.prod(shape, dtype=object)) * dtype.itemsize
        if size > MAX_NPZ_MEMBER_BYTES:
            name = info.filename.removesuffix(".npy")
            raise InputError(
                f"the array '{name[:60]}' declares {size} bytes, more than the "
                f"{MAX_NPZ_MEMBER_BYTES >> 20} MiB acscal reads from one NPZ array",
                path=path,
            )


def npz_arrays_from_bytes(data: bytes, path: Path) -> dict[str, np.ndarray]:
    """All arrays of an NPZ archive held in memory; any failure is an InputError naming
    ``path``."""
    try:
        z = np.load(io.BytesIO(data), allow_pickle=False)
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise InputError("is a single .npy array, not an NPZ archive", path=path)
        with z:
            check_npz_members(z, path)
            return {str(k): np.asarray(z[k]) for k in z.files}
    except InputError:
        raise
    except Exception as exc:  # corrupt archives raise many types (zipfile, zlib, ValueError)
        raise InputError(
            f"not a readable NPZ file (truncated or corrupt?): {type(exc).__name__}", path=path
        ) from exc


def _npz_scalar_str(arrays: Mapping[str, np.ndarray], key: str, path: Path) -> str:
    a = arrays[key]
    if a.ndim != 0 or a.dtype.kind not in "US":
        raise InputError(f"'{key}' must be a string", path=path)
    v = a[()]
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def _npz_numeric(arrays: Mapping[str, np.ndarray], key: str, path: Path) -> FloatArray:
    a = arrays[key]
    if a.dtype.kind not in "biuf":
        raise InputError(f"'{key}' must be numeric, got dtype {a.dtype}", path=path)
    return np.asarray(a, dtype=float)


def _check_npz_schema(arrays: Mapping[str, np.ndarray], path: Path) -> None:
    if "schema" in arrays:
        schema = _npz_scalar_str(arrays, "schema", path)
        if schema != NPZ_SCHEMA:
            raise InputError(
                f"this is a {schema} artifact, expected {NPZ_SCHEMA}; check the file is the "
                "output of `acscal poses`",
                path=path,
            )
    if "schema_version" in arrays:
        v = arrays["schema_version"]
        if v.ndim != 0 or v.dtype.kind not in "iu":
            raise InputError("'schema_version' must be an integer", path=path)
        if int(v) > NPZ_SCHEMA_VERSION:
            raise InputError(
                f"schema_version {int(v)} was written by a newer acscal (this one reads up "
                f"to {NPZ_SCHEMA_VERSION}); upgrade acscal",
                path=path,
            )


def parse_npz_poses(arrays: Mapping[str, np.ndarray], p: Path) -> Trajectory:
    """The trajectory of an NPZ's arrays (written by ``acscal poses`` or a plain one).

    ``T_world_cam`` (n, 4, 4) and optionally ``timestamps`` (n,) seconds, ``image_names``
    (n,) str, ``has_timestamps`` (bool), ``schema`` (= :data:`NPZ_SCHEMA`), ``schema_version``
    (int) and ``reprojection_rms`` (n,) px. Rotation blocks are re-orthonormalised; without
    ``timestamps`` the timestamps are the indices and ``has_timestamps`` is False.
    """
    _check_npz_schema(arrays, p)
    if "T_world_cam" not in arrays:
        raise InputError("has no 'T_world_cam' array of shape (n, 4, 4)", path=p)
    T = _npz_numeric(arrays, "T_world_cam", p)
    if T.ndim != 3 or T.shape[1:] != (4, 4) or T.shape[0] == 0:
        raise InputError(f"'T_world_cam' must have shape (n, 4, 4), got {T.shape}", path=p)
    n = T.shape[0]
    if not np.all(np.isfinite(T)):
        k = int(np.flatnonzero(~np.isfinite(T).reshape(n, -1).all(axis=1))[0])
        raise InputError(f"T_world_cam[{k}] contains NaN or inf", path=p)
    if np.abs(T[:, 3, :] - [0.0, 0.0, 0.0, 1.0]).max() > KITTI_ORTHONORMAL_TOL:
        raise InputError("every T_world_cam must have a last row of [0, 0, 0, 1]", path=p)
    R = _check_rotation_blocks(T[:, :3, :3], None, p, "T_world_cam")
    T = se3.transforms_from_rt(R, T[:, :3, 3]).reshape(-1, 4, 4)

    if "timestamps" in arrays:
        t = _npz_numeric(arrays, "timestamps", p)
        if t.shape != (n,):
            raise InputError(f"'timestamps' must have shape ({n},), got {t.shape}", path=p)
        has_t = True
        if "has_timestamps" in arrays:
            h = arrays["has_timestamps"]
            if h.ndim != 0 or h.dtype.kind not in "biu":
                raise InputError("'has_timestamps' must be a boolean", path=p)
            has_t = bool(h)
    else:
        t = np.arange(n, dtype=float)
        has_t = False

    names: tuple[str, ...] = ()
    if "image_names" in arrays:
        a = arrays["image_names"]
        if a.dtype.kind not in "US" or a.shape != (n,):
            raise InputError(f"'image_names' must be {n} strings, got {a.dtype} {a.shape}", path=p)
        decoded = [v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v) for v in a]
        if any(decoded):
            names = tuple(decoded)
    ns = None
    if "timestamps_ns" in arrays:
        ns = arrays["timestamps_ns"]
        if ns.dtype.kind not in "iu" or ns.shape != (n,):
            raise InputError(f"'timestamps_ns' must be {n} integers, got {ns.shape}", path=p)
    unit = _npz_scalar_str(arrays, "time_unit", p) if "time_unit" in arrays else "s"
    if "reprojection_rms" in arrays:
        rms = arrays["reprojection_rms"]
        if rms.dtype.kind not in "biuf" or rms.shape != (n,):
            raise InputError(f"'reprojection_rms' must be {n} numbers, got {rms.shape}", path=p)
    return Trajectory(
        t,
        T,
        source=str(p),
        format="npz",
        has_timestamps=has_t,
        names=names,
        timestamps_ns=ns,
        time_unit=unit,
    )


def parse_npz_header(arrays: Mapping[str, np.ndarray], p: Path) -> dict[str, Any]:
    """The header stored in an NPZ's arrays (``header_json``), or ``{}``."""
    if "header_json" not in arrays:
        return {}
    try:
        header = json.loads(_npz_scalar_str(arrays, "header_json", p))
    except (ValueError, RecursionError) as exc:  # RecursionError: nested too deeply
        raise InputError("'header_json' is not valid JSON (or nested too deeply)", path=p) from exc
    if not isinstance(header, dict):
        raise InputError("'header_json' is not a mapping", path=p)
    return header


def parse_npz_observations(
    arrays: Mapping[str, np.ndarray], p: Path
) -> tuple[FloatArray, FloatArray] | None:
    """The corners ``(n, m, 2)`` (pixels; NaN where a view did not see the target's corner
    ``j``) and board points ``(m, 3)`` (metres, every corner of the target) stored by
    ``acscal poses`` in an NPZ's arrays, or ``None`` without them.

    Raises
    ------
    InputError
        Infinite corners, board points that are not finite, or absurd magnitudes (their
        shapes are :meth:`acs_cli.io.poses.PosesArtifact.validate`'s to check).
    """
    if "corners" not in arrays or "board_points" not in arrays:
        return None
    corners = _npz_numeric(arrays, "corners", p)
    board = _npz_numeric(arrays, "board_points", p)
    # a corner a view did not see is NaN (a partial view of an AprilGrid or ChArUco target)
    if np.any(np.isinf(corners)) or not np.all(np.isfinite(board)):
        raise InputError("'corners' contain inf, or 'board_points' NaN or inf", path=p)
    check_magnitude(corners, "corners", p)  # pixels
    check_magnitude(board, "board_points", p)  # metres
    return corners, board


def parse_npz_quality(arrays: Mapping[str, np.ndarray], p: Path) -> tuple[np.ndarray, list[str]]:
    """Per-pose reprojection RMS (px, ``(n,)``; empty when absent) and the names of the
    images without a pose, as ``acscal poses`` stores them in an NPZ's arrays.

    Raises
    ------
    InputError
        A non-numeric ``reprojection_rms``.
    """
    rms = (
        _npz_numeric(arrays, "reprojection_rms", p).reshape(-1)
        if "reprojection_rms" in arrays
        else np.zeros(0)
    )
    skipped = [str(v) for v in np.asarray(arrays.get("skipped_images", [])).reshape(-1)]
    return rms, skipped


def write_npz_poses(
    path: str | Path,
    traj: Trajectory,
    extra: Mapping[str, ArrayLike] | None = None,
    *,
    header: Mapping[str, Any] | None = None,
) -> None:
    """Write an ``acscal/poses`` NPZ atomically (compressed).

    Parameters
    ----------
    path : str or Path
        Destination file (any suffix; ``.npz`` is customary).
    traj : Trajectory
        Written as ``T_world_cam`` (n, 4, 4), ``timestamps`` (n,), ``has_timestamps``,
        ``image_names`` (n,) (empty strings when unknown).
    extra : mapping of str to array_like, optional
        More arrays, e.g. ``reprojection_rms`` (n,) in pixels. Must not use reserved keys
        or need pickling (object arrays).
    header : mapping, optional
        The artifact header (``artifacts.make_header``), stored as JSON in ``header_json``.

    Raises
    ------
    ValueError
        A reserved or non-string key, or an object array, in ``extra`` (a programming error).
    InputError
        The destination cannot be written.
    """
    n = len(traj)
    arrays: dict[str, np.ndarray] = {
        "schema": np.array(NPZ_SCHEMA),
        "schema_version": np.array(NPZ_SCHEMA_VERSION, dtype=np.int64),
        "T_world_cam": np.asarray(traj.T_world_cam, dtype=float),
        "timestamps": np.asarray(traj.timestamps, dtype=float),
        "has_timestamps": np.array(bool(traj.has_timestamps)),
        "image_names": np.array(list(traj.names) if traj.names else [""] * n, dtype=str),
        "time_unit": np.array(traj.time_unit),
    }
    if traj.timestamps_ns is not None:
        arrays["timestamps_ns"] = np.asarray(traj.timestamps_ns, dtype=np.int64)
    if header is not None:
        from acs_cli.io.artifacts import to_plain

        arrays["header_json"] = np.array(json.dumps(to_plain(dict(header))))
    for key, value in (extra or {}).items():
        if not isinstance(key, str) or key in _NPZ_RESERVED:
            raise ValueError(f"extra key {key!r} is reserved or not a string")
        arr = np.asarray(value)
        if arr.dtype.kind == "O":
            raise ValueError(f"extra array {key!r} has dtype object (would need pickling)")
        arrays[key] = arr
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------
# dispatch

_PARSERS: dict[str, Callable[[str, Path], Trajectory]] = {
    "tum": _parse_tum,
    "kitti": _parse_kitti,
    "colmap": _parse_colmap,
}


_SCHEMA_LINE = re.compile(r"^schema:\s*['\"]?(acscal/[\w.-]+)")


def read_input(path: str | Path, fmt: str = "auto") -> tuple[Path, bytes, str]:
    """The file a trajectory input names (a COLMAP folder's ``images.txt``), its bytes (the
    one read) and its format (for :func:`read_trajectory`'s ``path`` and ``fmt``): an NPZ
    by its ``.npz`` suffix or its content (a zip archive); ``"auto"`` left for a text file
    whose first data line tells (:func:`parse_trajectory`).

    Raises
    ------
    InputError
        An unknown ``fmt``; a missing, unreadable or too large file; a folder without
        ``images.txt``.
    """
    p = Path(path)
    if fmt not in FORMATS:
        raise InputError(f"unknown trajectory format {fmt!r}; use one of {', '.join(FORMATS)}")
    if fmt == "colmap" or (fmt == "auto" and (p.is_dir() or p.name == "images.txt")):
        p, fmt = _colmap_file(p), "colmap"
    npz = fmt == "npz" or (fmt == "auto" and p.suffix.lower() == ".npz")
    data = read_input_bytes(
        p, "an NPZ file" if npz else "a trajectory file", max(MAX_NPZ_BYTES, MAX_TEXT_BYTES)
    )
    if fmt == "auto" and (npz or data[:4] == b"PK\x03\x04"):  # a zip archive: an NPZ
        fmt = "npz"
    if fmt != "npz" and len(data) > MAX_TEXT_BYTES:
        raise InputError(
            f"is larger than the {MAX_TEXT_BYTES >> 30} GiB acscal reads as a trajectory file",
            path=p,
        )
    return p, data, fmt


def parse_trajectory(p: Path, data: bytes, fmt: str) -> Trajectory:
    """The trajectory in the bytes :func:`read_input` read from ``p`` (format ``fmt``).

    Raises
    ------
    InputError
        An undecidable format, or the format's reader's error.
    """
    if fmt == "npz":
        return parse_npz_poses(npz_arrays_from_bytes(data, p), p)
    text = _decode_text(data, p)
    return _PARSERS[_sniff(text, p) if fmt == "auto" else fmt](text, p)


def _sniff(text: str, path: Path) -> str:
    first = _first_data_line(text)
    if first is None:
        raise InputError("contains no poses (empty file)", path=path)
    line, number = first
    schema = _SCHEMA_LINE.match(line)
    if schema:
        raise InputError(
            f"this is an {schema.group(1)} artifact, not a trajectory (TUM, KITTI, COLMAP "
            "images.txt or an acscal/poses NPZ)",
            path=path,
        )
    tokens = line.split()
    try:
        [float(tok) for tok in tokens]
    except ValueError:
        raise InputError(
            "not a trajectory: the first pose line is not numbers (TUM has 8 a line, KITTI 12)",
            path=path,
            line=number,
        ) from None
    if len(tokens) == 8:
        return "tum"
    if len(tokens) == 12:
        return "kitti"
    raise InputError(
        f"cannot tell the trajectory format from a first line of {len(tokens)} numbers (TUM "
        "has 8, KITTI 12); give the format explicitly",
        path=path,
        line=number,
    )


def read_trajectory(path: str | Path, fmt: str = "auto") -> Trajectory:
    """Read a trajectory in any supported format (in one read of its bytes).

    Parameters
    ----------
    path : str or Path
        A TUM or KITTI text file, a COLMAP ``images.txt`` or its folder, or an NPZ.
    fmt : {"auto", "tum", "kitti", "colmap", "npz"}
        ``"auto"``: ``.npz`` or a zip archive is NPZ; a folder or ``images.txt`` is COLMAP;
        otherwise the first data line decides: 8 numbers TUM, 12 KITTI.

    Returns
    -------
    Trajectory

    Raises
    ------
    InputError
        A missing file, an unknown ``fmt``, an undecidable format, or a reader's error.
    """
    return parse_trajectory(*read_input(path, fmt))
