"""Target descriptions: Kalibr's and OpenCV's target YAML files and the ``--target`` short forms.

A target YAML names its kind in ``target_type`` and its geometry with the names of the tool
it comes from (lengths in metres):

- ``aprilgrid`` (Kalibr's file as it is): ``tagCols``, ``tagRows``, ``tagSize``,
  ``tagSpacing`` (gap / tagSize). Kalibr's ``codeOffset`` is accepted when 0.
- ``charuco`` (OpenCV's names): ``squaresX``, ``squaresY``, ``squareLength``,
  ``markerLength``, ``dictionary`` (e.g. ``DICT_5X5_100``).
- ``checkerboard`` (Kalibr's names): ``targetCols``, ``targetRows`` (inner corners),
  ``rowSpacingMeters``, ``colSpacingMeters`` (equal: acscal's boards have square squares).

Short forms: ``aprilgrid:6x6:0.088:0.3`` (tags, tag size, spacing),
``charuco:11x8:0.03:0.022:DICT_5X5_100`` (squares, square, marker, dictionary) and
``checkerboard:9x6:0.025`` (inner corners, square).

Every problem is an :class:`~acs_cli.errors.InputError` naming the file (or the option)
and the key.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import yaml

from acs_cli.core.targets import (
    ARUCO_DICTIONARIES,
    TARGET_KINDS,
    AprilGrid,
    Charuco,
    Checkerboard,
    Target,
)
from acs_cli.errors import InputError
from acs_cli.io.artifacts import load_yaml_file
from acs_cli.io.atomic import atomic_write_text
from acs_cli.io.validate import (
    MAX_MAGNITUDE,
    as_int,
    as_mapping,
    as_number,
    check_magnitude,
)

__all__ = [
    "parse_target",
    "parse_target_short",
    "read_target_yaml",
    "target_from_mapping",
    "target_to_mapping",
    "write_target_yaml",
]

_SIZE = re.compile(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$")
Source = str | Path | None


def _int(d: Mapping[str, Any], key: str, path: Source, prefix: str, minimum: int) -> int:
    if key not in d:
        raise InputError(f"missing key '{prefix}{key}'", path=path)
    return as_int(d[key], prefix + key, path, minimum=minimum)


def _length(d: Mapping[str, Any], key: str, path: Source, prefix: str) -> float:
    if key not in d:
        raise InputError(f"missing key '{prefix}{key}'", path=path)
    v = as_number(d[key], prefix + key, path, positive=True)
    check_magnitude(v, prefix + key, path)
    return v


def _dictionary(value: Any, key: str, path: Source) -> str:
    if not isinstance(value, str) or value not in ARUCO_DICTIONARIES:
        shown = str(value)[:40]
        raise InputError(
            f"'{key}' must name an OpenCV ArUco dictionary (e.g. DICT_5X5_100, "
            f"DICT_APRILTAG_36h11), got {shown!r}",
            path=path,
        )
    return value


def _build(kind: str, key: str, path: Source, **kwargs: Any) -> Target:
    """The target, with a geometry error (e.g. a marker larger than its square) as an
    InputError naming ``key``."""
    cls: Any = {"checkerboard": Checkerboard, "aprilgrid": AprilGrid, "charuco": Charuco}[kind]
    try:
        return cls(**kwargs)
    except ValueError as exc:
        raise InputError(f"{key}: {exc}" if key else str(exc), path=path) from exc


def target_from_mapping(doc: Any, path: Source = None, key: str = "") -> Target:
    """A target from its YAML mapping (see the module documentation).

    Parameters
    ----------
    doc : Any
        The parsed YAML (a mapping with ``target_type``).
    path : str or Path, optional
        The file, for messages.
    key : str
        The mapping's own key in a larger document (e.g. ``"target"``), for messages.

    Returns
    -------
    Checkerboard, AprilGrid or Charuco

    Raises
    ------
    InputError
        Not a mapping, a missing or unknown ``target_type``, or a missing key or a value of
        the wrong type, naming the key.
    """
    prefix = f"{key}." if key else ""
    d = as_mapping(doc, key or "target", path)
    kind = d.get("target_type")
    if not isinstance(kind, str) or kind.lower() not in TARGET_KINDS:
        raise InputError(
            f"'{prefix}target_type' must be one of {', '.join(TARGET_KINDS)}, got "
            f"{str(kind)[:40]!r}",
            path=path,
        )
    kind = kind.lower()
    where = ""
    if kind == "aprilgrid":
        offset = d.get("codeOffset", 0)
        if as_int(offset, prefix + "codeOffset", path) != 0:
            raise InputError(
                f"'{prefix}codeOffset' {offset} is not supported (only grids whose first tag "
                "is id 0)",
                path=path,
            )
        return _build(
            kind,
            where,
            path,
            tag_cols=_int(d, "tagCols", path, prefix, 1),
            tag_rows=_int(d, "tagRows", path, prefix, 1),
            tag_size=_length(d, "tagSize", path, prefix),
            spacing=_length(d, "tagSpacing", path, prefix),
        )
    if kind == "charuco":
        if "dictionary" not in d:
            raise InputError(f"missing key '{prefix}dictionary'", path=path)
        square = _length(d, "squareLength", path, prefix)
        marker = _length(d, "markerLength", path, prefix)
        if marker >= square:
            raise InputError(
                f"'{prefix}markerLength' ({marker}) must be less than '{prefix}squareLength' "
                f"({square})",
                path=path,
            )
        return _build(
            kind,
            where,
            path,
            squares_x=_int(d, "squaresX", path, prefix, 3),
            squares_y=_int(d, "squaresY", path, prefix, 3),
            square_length=square,
            marker_length=marker,
            dictionary=_dictionary(d["dictionary"], prefix + "dictionary", path),
        )
    row = _length(d, "rowSpacingMeters", path, prefix)
    col = _length(d, "colSpacingMeters", path, prefix)
    if abs(row - col) > 1e-9 * max(row, col):
        raise InputError(
            f"'{prefix}rowSpacingMeters' ({row}) and '{prefix}colSpacingMeters' ({col}) differ: "
            "acscal's checkerboards have square squares",
            path=path,
        )
    return _build(
        kind,
        where,
        path,
        cols=_int(d, "targetCols", path, prefix, 2),
        rows=_int(d, "targetRows", path, prefix, 2),
        square=row,
    )


def target_to_mapping(target: Target) -> dict[str, Any]:
    """The YAML mapping of a target (Kalibr's names, OpenCV's for ChArUco); the inverse of
    :func:`target_from_mapping`."""
    if isinstance(target, AprilGrid):
        return {
            "target_type": "aprilgrid",
            "tagCols": target.tag_cols,
            "tagRows": target.tag_rows,
            "tagSize": float(target.tag_size),
            "tagSpacing": float(target.spacing),
        }
    if isinstance(target, Charuco):
        return {
            "target_type": "charuco",
            "squaresX": target.squares_x,
            "squaresY": target.squares_y,
            "squareLength": float(target.square_length),
            "markerLength": float(target.marker_length),
            "dictionary": target.dictionary,
        }
    return {
        "target_type": "checkerboard",
        "targetCols": target.cols,
        "targetRows": target.rows,
        "rowSpacingMeters": float(target.square),
        "colSpacingMeters": float(target.square),
    }


def read_target_yaml(path: str | Path) -> Target:
    """Read a target YAML file (:func:`target_from_mapping`).

    Raises
    ------
    InputError
        An unreadable file, invalid YAML, or a bad target (naming the key).
    """
    return target_from_mapping(load_yaml_file(path, "a target YAML file"), Path(path))


def write_target_yaml(path: str | Path, target: Target) -> None:
    """Write a target YAML file atomically (:func:`target_to_mapping`)."""
    atomic_write_text(path, yaml.safe_dump(target_to_mapping(target), sort_keys=False))


def parse_target_short(text: str, option: str = "--target") -> Target:
    """A target from its short form (see the module documentation).

    Raises
    ------
    InputError
        An unknown kind, the wrong number of fields, or a field of the wrong type, naming
        the field.
    """
    parts = [p.strip() for p in text.split(":")]
    kind = parts[0].lower()
    forms = {
        "aprilgrid": ("COLSxROWS", "tagSize", "tagSpacing"),
        "charuco": ("SQUARESXxSQUARESY", "squareLength", "markerLength", "dictionary"),
        "checkerboard": ("COLSxROWS", "square"),
    }
    if kind not in forms:
        raise InputError(
            f"{option} {text!r}: unknown target type {parts[0]!r}; use one of "
            f"{', '.join(TARGET_KINDS)} (or a target YAML file)"
        )
    fields = forms[kind]
    if len(parts) != len(fields) + 1:
        raise InputError(f"{option} {text!r}: expected {kind}:{':'.join(fields)}")
    m = _SIZE.match(parts[1])
    if not m:
        raise InputError(f"{option} {text!r}: {fields[0]} must look like 6x6, got {parts[1]!r}")
    a, b = int(m.group(1)), int(m.group(2))
    lengths: list[float] = []
    for name, value in zip(fields[1:], parts[2:], strict=False):
        if name == "dictionary":
            continue
        try:
            v = float(value)
        except ValueError:
            v = float("nan")
        if not 0 < v <= MAX_MAGNITUDE:
            raise InputError(
                f"{option} {text!r}: {name} must be a positive number (at most "
                f"{MAX_MAGNITUDE:.0e}), got {value!r}"
            )
        lengths.append(v)
    where = f"{option} {text!r}"
    if kind == "aprilgrid":
        return _build(kind, where, None, tag_cols=a, tag_rows=b, tag_size=lengths[0],
                      spacing=lengths[1])  # fmt: skip
    if kind == "charuco":
        return _build(
            kind,
            where,
            None,
            squares_x=a,
            squares_y=b,
            square_length=lengths[0],
            marker_length=lengths[1],
            dictionary=_dictionary(parts[4], f"{option} dictionary", None),
        )
    return _build(kind, where, None, cols=a, rows=b, square=lengths[0])


def parse_target(text: str, option: str = "--target") -> Target:
    """``--target FILE|SHORT``: a short form when ``text`` has a colon and names no existing
    file, else a target YAML file."""
    if ":" in text and not Path(text).exists():
        return parse_target_short(text, option)
    return read_target_yaml(text)
