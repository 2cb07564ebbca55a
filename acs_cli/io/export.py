"""Exports to other tools: Kalibr camchain YAML and OpenCV ``FileStorage`` YAML."""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from numpy.typing import NDArray

from acs_cli.errors import InputError
from acs_cli.io.artifacts import to_plain
from acs_cli.io.atomic import atomic_path, atomic_write_text

__all__ = ["read_opencv_yaml", "write_camchain_yaml", "write_opencv_yaml"]

_OPENCV_SUFFIXES = (".yaml", ".yml", ".xml", ".json")
_OPENCV_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")


def _intrinsics_4(value: Any, name: str) -> list[float]:
    """``[fu, fv, pu, pv]`` from 4 numbers or a 3x3 camera matrix ``K`` (pixels)."""
    arr = np.asarray(value, dtype=float)
    if arr.shape == (3, 3):
        arr = np.array([arr[0, 0], arr[1, 1], arr[0, 2], arr[1, 2]])
    if arr.shape != (4,) or not np.all(np.isfinite(arr)):
        raise InputError(f"camera {name}: intrinsics must be [fu, fv, pu, pv] or a 3x3 matrix")
    return [float(v) for v in arr]


def write_camchain_yaml(path: str | Path, cameras: Sequence[Mapping[str, Any]]) -> None:
    """Write a Kalibr-style camchain YAML (``cam0``, ``cam1``, ...) atomically.

    Parameters
    ----------
    path : str or Path
        Destination file.
    cameras : sequence of mapping
        One per camera, in chain order. Keys:

        - ``name`` (str, required): used for the default ``rostopic`` ``/<name>/image_raw``.
        - ``T_cn_cnm1`` ((4, 4), cameras 1.. only): maps points in camera n-1's frame into
          camera n's frame (lengths in the artifact's units).
        - ``intrinsics``: ``[fu, fv, pu, pv]`` or a 3x3 ``K`` in pixels (pinhole model);
          omitted when unknown, together with ``camera_model``.
        - ``distortion_coeffs``: radtan ``[k1, k2, p1, p2]``; omitted when unknown, together
          with ``distortion_model``.
        - ``resolution``: ``[width, height]`` in pixels; omitted when unknown.
        - ``rostopic``: overrides the default topic.

    Raises
    ------
    InputError
        A camera without a name, ``T_cn_cnm1`` on the first camera or not a rigid
        transform, bad intrinsics, or an unwritable destination.
    """
    doc: dict[str, Any] = {}
    for i, cam in enumerate(cameras):
        name = cam.get("name")
        if not isinstance(name, str) or not name:
            raise InputError(f"camera {i} needs a non-empty 'name'")
        entry: dict[str, Any] = {}
        if cam.get("T_cn_cnm1") is not None:
            from acs_cli.core import se3  # here: scipy's import costs every command ~0.5 s

            if i == 0:
                raise InputError(f"camera {name}: the first camera has no T_cn_cnm1")
            T = se3.check_transforms(cam["T_cn_cnm1"], name=f"camera {name} T_cn_cnm1")
            entry["T_cn_cnm1"] = to_plain(T[0])
        if cam.get("intrinsics") is not None:
            entry["camera_model"] = "pinhole"
            entry["intrinsics"] = _intrinsics_4(cam["intrinsics"], name)
        if cam.get("distortion_coeffs") is not None:
            entry["distortion_model"] = "radtan"
            entry["distortion_coeffs"] = [
                float(v) for v in np.asarray(cam["distortion_coeffs"], dtype=float).ravel()
            ]
        if cam.get("resolution") is not None:
            entry["resolution"] = [int(v) for v in np.asarray(cam["resolution"]).ravel()]
        entry["rostopic"] = str(cam.get("rostopic") or f"/{name}/image_raw")
        doc[f"cam{i}"] = entry
    text = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
    atomic_write_text(path, text)


def _cv_value(key: str, value: Any) -> Any:
    """A value ``cv2.FileStorage.write`` accepts."""
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value)
    arr = np.asarray(value)
    if arr.dtype.kind == "b":
        return arr.astype(np.uint8)
    if arr.dtype.kind in "iu":
        if arr.size and (arr.min() < np.iinfo(np.int32).min or arr.max() > np.iinfo(np.int32).max):
            return arr.astype(np.float64)
        return arr.astype(np.int32)
    if arr.dtype.kind == "f":
        return arr.astype(np.float64)
    raise TypeError(f"cannot write {key!r} of type {type(value).__name__} to OpenCV YAML")


def write_opencv_yaml(path: str | Path, mats: Mapping[str, Any]) -> None:
    """Write matrices and scalars with ``cv2.FileStorage``, atomically.

    Parameters
    ----------
    path : str or Path
        Destination; the format follows its suffix when it is ``.yaml``/``.yml``/``.xml``/
        ``.json``, else YAML.
    mats : mapping of str to ndarray, float, int or str
        Values by key. Arrays (at most 2-D is customary, e.g. ``K`` (3, 3), ``T_b_a``
        (4, 4)) are stored as ``opencv-matrix`` (float64, or int32 for integers).

    Raises
    ------
    ValueError
        A key OpenCV cannot store (keys must match ``[A-Za-z_][A-Za-z0-9_-]*``).
    TypeError
        A value of an unsupported type.
    InputError
        The destination cannot be written.
    """
    dest = Path(path)
    suffix = dest.suffix.lower() if dest.suffix.lower() in _OPENCV_SUFFIXES else ".yaml"
    values = {}
    for key, value in mats.items():
        if not _OPENCV_KEY.match(key):
            raise ValueError(f"OpenCV FileStorage cannot store the key {key!r}")
        values[key] = _cv_value(key, value)
    with atomic_path(dest, suffix=suffix) as tmp:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        try:
            if not fs.isOpened():
                raise InputError("cannot write (OpenCV could not open the file)", path=dest)
            for key, value in values.items():
                fs.write(key, value)
        finally:
            fs.release()


def read_opencv_yaml(
    path: str | Path, keys: Iterable[str]
) -> dict[str, NDArray[Any] | float | str]:
    """Read values written by :func:`write_opencv_yaml` (or any ``cv2.FileStorage`` file).

    Parameters
    ----------
    path : str or Path
        The file.
    keys : iterable of str
        Keys to read.

    Returns
    -------
    dict
        Matrices as ndarrays, numbers as float, strings as str.

    Raises
    ------
    InputError
        A missing or unparsable file, or a missing key.
    """
    p = Path(path)
    if not p.is_file():
        raise InputError("no such file", path=p)
    try:
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    except Exception as exc:  # cv2.error, or SystemError wrapping it on a parse error
        raise InputError("not a readable OpenCV FileStorage file", path=p) from exc
    out: dict[str, NDArray[Any] | float | str] = {}
    try:
        if not fs.isOpened():
            raise InputError("not a readable OpenCV FileStorage file", path=p)
        for key in keys:
            node = fs.getNode(key)
            if node.empty() or node.isNone():
                raise InputError(f"missing key '{key}'", path=p)
            if node.isString():
                out[key] = node.string()
            elif node.isInt() or node.isReal():
                out[key] = float(node.real())
            else:
                try:
                    mat = node.mat()
                except Exception:  # cv2.error: a malformed opencv-matrix node
                    mat = None
                if mat is None:
                    raise InputError(f"'{key}' is not a matrix, number or string", path=p)
                out[key] = np.asarray(mat)
    finally:
        fs.release()
    return out
