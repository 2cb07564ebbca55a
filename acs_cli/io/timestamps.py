"""Image times: from file names, a timestamps file, or frame numbers and a frame rate.

Rules (``docs/conventions.md``, "Timestamps"), applied to the last number in a file's stem:

- a number with a decimal point is seconds: ``frame_1623456789.123.png`` is 1623456789.123 s;
- an integer of 18 digits or more is nanoseconds (ROS, EuRoC: ``1403636579763555584.png``),
  of 15-17 digits microseconds, of 12-14 digits milliseconds, of 9-11 digits seconds (Unix
  time);
- a shorter integer is a frame number (``img_00010.png`` is frame 10), not a time: without
  ``--fps`` the trajectory's times are frame numbers and every output says so.

``--timestamps FILE`` (a CSV of image name and time) overrides the names; ``--fps F`` turns
frame numbers (or, for names without numbers, the images' order in the folder) into seconds.
Times are kept as exact integer nanoseconds beside the seconds, so that a TUM file written
from them carries the digits the source had.
"""

from __future__ import annotations

import csv
import itertools
import re
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from acs_cli.errors import InputError
from acs_cli.io.atomic import MAX_TEXT_BYTES, read_input_bytes
from acs_cli.io.images import IMAGE_SUFFIXES

__all__ = [
    "VIDEO_TIMES",
    "ImageTimes",
    "NameStamp",
    "image_times",
    "read_timestamps_file",
    "stamp_from_name",
    "times_from_ns",
]

#: How artifacts name a video's frame times.
VIDEO_TIMES = "the video's presentation timestamps (pts * time_base)"

_NUMBER = re.compile(r"\d+(?:\.\d+)?")
#: Integer file-name stamps by their number of digits: (fewest digits, unit, ns per unit).
_INTEGER_UNITS = ((18, "nanoseconds", 1), (15, "microseconds", 1000), (12, "milliseconds", 10**6))
#: Integers of at least this many digits (and fewer than 12) are seconds of Unix time.
_SECONDS_DIGITS = 9
_NS = 10**9
#: Times at or beyond this many nanoseconds (int64's range, 292 years) are refused.
_NS_LIMIT = 2**63
_INTEGER = re.compile(r"^[+-]?\d+$")


@dataclass(frozen=True)
class NameStamp:
    """The time (or frame number) one file name carries.

    Attributes
    ----------
    unit : str
        ``"nanoseconds"``, ``"microseconds"``, ``"milliseconds"``, ``"seconds"`` or
        ``"frame"`` (a frame number, not a time).
    ns : int
        The time in integer nanoseconds (exact), or the frame number for ``"frame"``.
    """

    unit: str
    ns: int


def _exact_ns(token: str) -> int:
    """Integer nanoseconds of a decimal number of seconds, exactly (rounded past 9 digits)."""
    try:
        value = Decimal(token.strip())
    except InvalidOperation as exc:
        raise ValueError(f"not a number: {token!r}") from exc
    if not value.is_finite():
        raise ValueError(f"not a finite number: {token!r}")
    return int((value * _NS).to_integral_value())


def stamp_from_name(name: str) -> NameStamp | None:
    """The time (or frame number) in a file name, by the module's rules; None without one.

    ``img_00012.png`` gives frame 12, ``1403636579763555584.png`` 1403636579763555584 ns,
    ``frame_1623456789.123.png`` 1623456789.123 s, ``board.png`` None.
    """
    stem = Path(name).stem if Path(name).suffix.lower() in IMAGE_SUFFIXES else name
    found = _NUMBER.findall(stem)
    if not found:
        return None
    token = found[-1]
    if "." in token:
        return NameStamp("seconds", _exact_ns(token))
    digits = len(token.lstrip("0")) or 1
    value = int(token)
    for fewest, unit, factor in _INTEGER_UNITS:
        if digits >= fewest:
            return NameStamp(unit, value * factor)
    if digits >= _SECONDS_DIGITS:
        return NameStamp("seconds", value * _NS)
    return NameStamp("frame", value)


@dataclass(frozen=True)
class ImageTimes:
    """The times of a sequence of images.

    Attributes
    ----------
    seconds : ndarray, shape (n,)
        Strictly increasing times in seconds, or frame numbers when ``unit == "frame"``.
    nanoseconds : ndarray of int64, shape (n,), or None
        The same times as exact integer nanoseconds (None for frame numbers).
    unit : str
        ``"s"`` or ``"frame"``.
    source : str
        Where they came from, in words (recorded in artifacts' headers).
    has_timestamps : bool
        False when the only order is the images' place in the folder (pair by index).
    """

    seconds: NDArray[np.float64]
    nanoseconds: NDArray[np.int64] | None
    unit: str
    source: str
    has_timestamps: bool

    @property
    def note(self) -> str | None:
        """A warning for outputs whose times are not seconds, or None."""
        if self.unit == "s":
            return None
        return (
            f"times are {self.source}, not seconds: give --fps (the frame rate) or "
            "--timestamps FILE for times in seconds; pairing with other recordings and a "
            "time offset need them"
        )


def _check_name_times(names: list[str], stamps: list[NameStamp | None], increasing: bool) -> None:
    """Refuse image names whose times mix units, or do not increase in the images' order."""
    units = {s.unit for s in stamps if s is not None}
    if len(units) > 1:
        first: dict[str, str] = {}
        for n, s in zip(names, stamps, strict=True):
            if s is not None:
                first.setdefault(s.unit, n)
        shown = ", ".join(f"{n} ({u})" for u, n in first.items())
        raise InputError(
            f"the image names mix time units: {shown}; rename them, or give --timestamps FILE"
        )
    if not increasing:
        ns = [s.ns for s in stamps if s is not None]
        k = next(i for i in range(1, len(ns)) if ns[i] <= ns[i - 1])
        raise InputError(
            f"the times in the image names do not increase in the images' order: {names[k]} "
            f"comes after {names[k - 1]}; give --timestamps FILE"
        )


def _times_from_ns(ns: list[int], unit: str, source: str) -> ImageTimes:
    big = next((v for v in ns if abs(v) >= _NS_LIMIT), None)
    if big is not None:
        raise InputError(f"a time of {big} ns from {source} is out of range (beyond 292 years)")
    arr = np.array(ns, dtype=np.int64)
    whole, frac = np.divmod(arr, _NS)
    seconds = whole.astype(float) + frac.astype(float) / _NS
    return ImageTimes(seconds, arr, unit, source, True)


def times_from_ns(ns: list[int], source: str) -> ImageTimes:
    """Times in seconds from strictly increasing integer nanoseconds (e.g. a video's
    presentation timestamps), named ``source``.

    Raises
    ------
    InputError
        Times beyond int64 nanoseconds.
    """
    return _times_from_ns(ns, "s", source)


def _check_increasing(names: list[str], ns: list[int], source: str) -> None:
    for k in range(1, len(ns)):
        if ns[k] <= ns[k - 1]:
            raise InputError(
                f"the times from {source} do not increase in the images' order: "
                f"{names[k]} is not after {names[k - 1]}"
            )


#: Unit words a timestamps file's header may carry, and nanoseconds per unit.
_HEADER_UNITS = (
    (re.compile(r"\[ns\]|\(ns\)|\bns\b|_ns\b|nanosec"), 1),
    (re.compile(r"\[us\]|\(us\)|\bus\b|_us\b|microsec|\[\u00b5s\]"), 1000),
    (re.compile(r"\[ms\]|\(ms\)|\bms\b|_ms\b|millisec"), 10**6),
)


def read_timestamps_file(path: str | Path) -> dict[str, int]:
    """Read a timestamps file: one image name and one time per line.

    CSV (comma, semicolon or tab; quoted fields allowed), the name and the time in either
    order; blank lines and lines starting with ``#`` are skipped, and a first line without a
    number is a header. Times are seconds (decimals kept exactly), unless the header names
    another unit (``[ns]``, ``t_ns``, ``(us)``, ``[ms]``, ...: EuRoC's ``data.csv`` is
    ``#timestamp [ns],filename``) or every time is an integer whose digits say it is not
    seconds, by the file-name rules (18 digits or more: nanoseconds; 15-17: microseconds;
    12-14: milliseconds).

    Returns
    -------
    dict of str to int
        Image file name (without folders) to time in integer nanoseconds.

    Raises
    ------
    InputError
        Unreadable file, a line without exactly one name and one time, a time that is not a
        finite number, a repeated name, a time beyond int64 nanoseconds, or no entries.
    """
    p = Path(path)
    data = read_input_bytes(p, "a timestamps file", MAX_TEXT_BYTES)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"cannot read the timestamps file ({exc})", path=p) from exc
    lines = text.splitlines()
    sample = "\n".join(ln for ln in lines[:20] if ln.strip() and not ln.lstrip().startswith("#"))
    delimiter = next((d for d in ",;\t" if d in sample), " ")
    header = ""
    rows: list[tuple[int, str, str]] = []
    reader = csv.reader(lines, delimiter=delimiter, skipinitialspace=True)
    for k, raw in enumerate(reader, start=1):
        fields = [f.strip() for f in raw if f.strip()]
        if not fields:
            continue
        if fields[0].startswith("#"):
            header += " ".join(fields).lower()
            continue
        numeric = [_is_number(f) for f in fields]
        if not rows and not any(numeric) and not any(_is_image_name(f) for f in fields):
            header += " " + " ".join(fields).lower()  # column names
            continue
        if len(fields) != 2:
            raise InputError(
                f"expected an image name and a time, got {len(fields)} field(s)", path=p, line=k
            )
        # the name is the field with an image suffix, else the one that is not a number
        name_first = _is_image_name(fields[0]) or (not _is_image_name(fields[1]) and not numeric[0])
        name, time = (fields[0], fields[1]) if name_first else (fields[1], fields[0])
        if not _is_number(time):
            raise InputError(f"not a time: {time!r}", path=p, line=k)
        rows.append((k, Path(name.replace("\\", "/")).name, time))
    if not rows:
        raise InputError("the timestamps file has no entries", path=p)
    factor = next((f for pattern, f in _HEADER_UNITS if pattern.search(header)), None)
    if factor is None and all(_INTEGER.match(t) for _, _, t in rows):
        digits = min(len(t.lstrip("+0")) for _, _, t in rows)
        factor = next((f for fewest, _, f in _INTEGER_UNITS if digits >= fewest), None)
    out: dict[str, int] = {}
    for k, name, time in rows:
        if name in out:
            raise InputError(f"{name} is listed twice", path=p, line=k)
        ns = _exact_ns(time) if factor is None else int(Decimal(time) * factor)
        if abs(ns) >= _NS_LIMIT:
            raise InputError(f"time {time} is out of range", path=p, line=k)
        out[name] = ns
    return out


def _is_number(s: str) -> bool:
    """A finite decimal number (``1.5``, ``-2``, ``1e3``; not ``NaN``, ``0x10``)."""
    try:
        return Decimal(s).is_finite()
    except InvalidOperation:
        return False


def _is_image_name(s: str) -> bool:
    return Path(s).suffix.lower() in IMAGE_SUFFIXES


def image_times(
    names: list[str],
    all_names: list[str],
    *,
    timestamps: dict[str, int] | None = None,
    timestamps_source: str = "the timestamps file",
    fps: float | None = None,
) -> ImageTimes:
    """The times of the images ``names`` (a subsequence of the folder's ``all_names``).

    Parameters
    ----------
    names : list of str
        The images kept (e.g. those with a board pose), in folder order.
    all_names : list of str
        Every image of the folder, in order (the fallback: their index).
    timestamps : dict of str to int, optional
        From :func:`read_timestamps_file`: overrides the names.
    timestamps_source : str
        How to name that file in messages.
    fps : float, optional
        Frames per second: frame numbers (or folder indices) become seconds.

    Returns
    -------
    ImageTimes

    Raises
    ------
    InputError
        ``timestamps`` and ``fps`` together, a non-positive ``fps``, ``fps`` for names
        that carry times, images missing from ``timestamps``, or times that do not increase.
    """
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise InputError(f"--fps must be a positive frame rate, got {fps}")
    if timestamps is not None:
        if fps is not None:
            raise InputError("give either --timestamps or --fps, not both")
        missing = [n for n in names if n not in timestamps]
        if missing:
            raise InputError(
                f"{len(missing)} image(s) are not in {timestamps_source}: "
                + ", ".join(missing[:5])
                + (" ..." if len(missing) > 5 else "")
            )
        ns = [timestamps[n] for n in names]
        _check_increasing(names, ns, timestamps_source)
        return _times_from_ns(ns, "s", timestamps_source)
    stamps = [stamp_from_name(n) for n in names]
    units = {s.unit for s in stamps if s is not None}
    every = all(s is not None for s in stamps)
    ns = [s.ns for s in stamps if s is not None]
    increasing = every and all(b > a for a, b in itertools.pairwise(ns))
    if every and units - {"frame"}:
        # names that carry times are used as such, or refused: never silently replaced
        _check_name_times(names, stamps, increasing)
        unit = units.pop()
        if fps is not None:
            raise InputError(
                f"--fps applies to frame numbers, but the image names carry times ({unit}); "
                "drop --fps"
            )
        return _times_from_ns(ns, "s", f"file names ({unit})")
    if increasing:
        frames = ns
        what = "frame numbers in the file names"
    else:
        index = {n: i for i, n in enumerate(all_names)}
        frames = [index[n] for n in names]
        what = "the images' order in the folder"
    if fps is not None:
        ns_fps = [round(f * _NS / fps) for f in frames]
        return _times_from_ns(ns_fps, "s", f"{what} at {fps:g} frames per second")
    return ImageTimes(np.array(frames, dtype=float), None, "frame", what, increasing)
