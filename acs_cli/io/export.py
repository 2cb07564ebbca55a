"""Exports of one camera to other tools: OpenCV ``FileStorage`` files and ROS ``camera_info``.

:func:`write_opencv_yaml` writes matrices, numbers, strings and one level of named maps with
``cv2.FileStorage`` itself; :func:`opencv_camera_values` are a camera's keys in it
(``camera_matrix``, ``distortion_coefficients``, ``image_width``, ``image_height``).
:func:`ros_camera_info_text` is the ``camera_info`` YAML of camera_calibration_parsers
(what ``camera_info_manager`` loads). The Kalibr camchain is in
:mod:`acs_cli.io.rig_export`.
"""

from __future__ import annotations

import gzip
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml
from numpy.typing import ArrayLike, NDArray

from acs_cli.errors import InputError
from acs_cli.io.atomic import atomic_write_bytes, atomic_write_text

__all__ = [
    "METRES_PER_UNIT",
    "ROS_DISTORTION_MODELS",
    "check_ros_camera_name",
    "opencv_camera_values",
    "ros_camera_info_text",
    "write_opencv_yaml",
    "write_ros_camera_info",
]

_OPENCV_SUFFIXES = (".yaml", ".yml", ".xml", ".json")
_OPENCV_KEY = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")
#: camera_info_manager's rule for a camera name: letters, digits and underscores.
_ROS_NAME = re.compile(r"^[A-Za-z0-9_]+$")

#: Metres per unit of the length units acscal converts by itself (``--length-unit`` of an
#: export, a joint file in other units than its trajectories).
METRES_PER_UNIT = {"m": 1.0, "cm": 0.01, "mm": 0.001, "km": 1000.0, "in": 0.0254, "ft": 0.3048}
#: ROS ``distortion_model`` (sensor_msgs/distortion_models.h) of each acscal camera model.
ROS_DISTORTION_MODELS = {
    "pinhole": "plumb_bob",
    "rational": "rational_polynomial",
    "fisheye": "equidistant",
}
#: Distortion coefficients of each acscal model (OpenCV's order), as ROS expects them.
_N_COEFFS = {"pinhole": 5, "rational": 8, "fisheye": 4}


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


def _cv_values(mats: Mapping[str, Any], where: str = "") -> dict[str, Any]:
    """Every value as :func:`_cv_value` makes it; a mapping (one level) as a dict of them."""
    values: dict[str, Any] = {}
    for key, value in mats.items():
        if not _OPENCV_KEY.match(key):
            raise ValueError(f"OpenCV FileStorage cannot store the key {where + key!r}")
        if isinstance(value, Mapping):
            if where:
                raise TypeError(f"cannot write {where + key!r}: maps nest one level only")
            values[key] = _cv_values(value, f"{key}.")
        else:
            values[key] = _cv_value(where + key, value)
    return values


def write_opencv_yaml(
    path: str | Path, mats: Mapping[str, Any], *, comments: Sequence[str] = ()
) -> None:
    """Write matrices, scalars and named maps of them with ``cv2.FileStorage``, atomically.

    Parameters
    ----------
    path : str or Path
        Destination; the format follows its suffix when it is ``.yaml``/``.yml``/``.xml``/
        ``.json``, else YAML. A name ending in ``.gz`` (``relpose.xml.gz``) is written
        gzip-compressed, as ``cv2.FileStorage`` does (and reads back).
    mats : mapping of str to ndarray, float, int, str or mapping
        Values by key. Arrays (at most 2-D is customary, e.g. ``K`` (3, 3), ``T_b_a``
        (4, 4)) are stored as ``opencv-matrix`` (float64, or int32 for integers). A mapping
        of such values is stored as a named map (one level: ``fs["cam_a"]["camera_matrix"]``).
    comments : sequence of str
        Lines written as comments at the top (YAML and XML only; JSON has none).

    Raises
    ------
    ValueError
        A key OpenCV cannot store (keys must match ``[A-Za-z_][A-Za-z0-9_-]*``).
    TypeError
        A value of an unsupported type, or maps nested deeper than one level.
    InputError
        The destination cannot be written.
    """
    dest = Path(path)
    gz = dest.suffix.lower() == ".gz"
    inner = Path(dest.stem).suffix.lower() if gz else dest.suffix.lower()
    suffix = inner if inner in _OPENCV_SUFFIXES else ".yaml"
    values = _cv_values(mats)
    # Written in memory (the format chosen by the suffix), then by the one atomic writer,
    # which checks every byte reached the disk: cv2.FileStorage's own file writes ignore
    # a full disk or a file-size limit.
    fs = cv2.FileStorage("out" + suffix, cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    try:
        if not fs.isOpened():  # pragma: no cover - memory storage always opens
            raise InputError("cannot write (OpenCV could not start the file)", path=dest)
        if suffix != ".json":
            for line in comments:
                fs.writeComment(" ".join(str(line).split()))
        for key, value in values.items():
            if isinstance(value, dict):
                fs.startWriteStruct(key, cv2.FileNode_MAP)
                for k, v in value.items():
                    fs.write(k, v)
                fs.endWriteStruct()
            else:
                fs.write(key, value)
        data = fs.releaseAndGetString().encode("utf-8")
    finally:
        fs.release()
    atomic_write_bytes(dest, gzip.compress(data, mtime=0) if gz else data)


def _camera_arrays(
    camera_matrix: ArrayLike, distortion: ArrayLike, image_size: Sequence[int], model: str
) -> tuple[NDArray[np.float64], NDArray[np.float64], tuple[int, int]]:
    """``K`` (3, 3), the coefficients and ``(width, height)``, checked against ``model``."""
    if model not in _N_COEFFS:
        raise InputError(f"unknown camera model {model!r}; use one of {', '.join(_N_COEFFS)}")
    K = np.asarray(camera_matrix, dtype=float)
    D = np.asarray(distortion, dtype=float).ravel()
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise InputError("the camera matrix must be a finite 3x3 K")
    if D.size != _N_COEFFS[model] or not np.all(np.isfinite(D)):
        raise InputError(f"the {model} model needs {_N_COEFFS[model]} finite coefficients")
    size = tuple(int(v) for v in image_size)
    if len(size) != 2 or min(size) <= 0:
        raise InputError("the image size must be [width, height] in pixels")
    return K, D, (size[0], size[1])


def opencv_camera_values(
    camera_matrix: ArrayLike, distortion: ArrayLike, image_size: Sequence[int], model: str
) -> dict[str, Any]:
    """A camera's keys in an OpenCV ``FileStorage`` file (for :func:`write_opencv_yaml`).

    Parameters
    ----------
    camera_matrix : array_like, shape (3, 3)
        ``K``, pixels.
    distortion : array_like
        OpenCV's order: pinhole ``k1 k2 p1 p2 k3``, rational ``k1 k2 p1 p2 k3 k4 k5 k6``,
        fisheye ``k1 k2 k3 k4`` (``cv2.fisheye``).
    image_size : sequence of int
        ``(width, height)``, pixels.
    model : {"pinhole", "rational", "fisheye"}

    Returns
    -------
    dict
        ``image_width``, ``image_height`` (int), ``model`` (str), ``camera_matrix`` (3x3)
        and ``distortion_coefficients`` (1xN), the keys OpenCV's calibration samples use.

    Raises
    ------
    InputError
        An unknown model, or values that do not fit it.
    """
    K, D, size = _camera_arrays(camera_matrix, distortion, image_size, model)
    return {
        "image_width": size[0],
        "image_height": size[1],
        "model": model,
        "camera_matrix": K,
        "distortion_coefficients": D.reshape(1, -1),
    }


def check_ros_camera_name(name: str) -> str:
    """``name`` if ``camera_info_manager`` accepts it (letters, digits, ``_``), else raise.

    Raises
    ------
    InputError
        An empty name or one with other characters.
    """
    if not isinstance(name, str) or not _ROS_NAME.match(name):
        raise InputError(
            f"camera name {name!r}: ROS camera names are letters, digits and underscores"
        )
    return name


def ros_camera_info_text(
    camera_matrix: ArrayLike,
    distortion: ArrayLike,
    image_size: Sequence[int],
    model: str,
    camera_name: str,
    *,
    comments: Sequence[str] = (),
) -> str:
    """A monocular camera's ROS ``camera_info`` YAML (camera_calibration_parsers' format).

    Keys, as ``sensor_msgs/CameraInfo`` holds them: ``image_width``, ``image_height``,
    ``camera_name``, ``camera_matrix`` (``K``, 3x3), ``distortion_model`` (``plumb_bob``,
    ``rational_polynomial`` or ``equidistant``), ``distortion_coefficients`` (``D``: 5, 8 or
    4 numbers), ``rectification_matrix`` (``R``: the identity) and ``projection_matrix``
    (``P``, 3x4: ``[K | 0]``); each matrix as ``{rows, cols, data}``, row-major.

    Parameters
    ----------
    camera_matrix, distortion, image_size, model
        As :func:`opencv_camera_values`.
    camera_name : str
        The name ``camera_info_manager`` compares with the camera driver's.
    comments : sequence of str
        Comment lines at the top.

    Returns
    -------
    str
        The YAML.

    Raises
    ------
    InputError
        A bad camera name, an unknown model, or values that do not fit it.
    """
    K, D, size = _camera_arrays(camera_matrix, distortion, image_size, model)
    check_ros_camera_name(camera_name)
    P = np.zeros((3, 4))
    P[:, :3] = K
    doc = {
        "image_width": size[0],
        "image_height": size[1],
        "camera_name": camera_name,
        "camera_matrix": {"rows": 3, "cols": 3, "data": K.ravel().tolist()},
        "distortion_model": ROS_DISTORTION_MODELS[model],
        "distortion_coefficients": {"rows": 1, "cols": int(D.size), "data": D.tolist()},
        "rectification_matrix": {"rows": 3, "cols": 3, "data": np.eye(3).ravel().tolist()},
        "projection_matrix": {"rows": 3, "cols": 4, "data": P.ravel().tolist()},
    }
    head = "".join(f"# {' '.join(str(c).split())}\n" for c in comments)
    return head + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)


def write_ros_camera_info(
    path: str | Path,
    camera_matrix: ArrayLike,
    distortion: ArrayLike,
    image_size: Sequence[int],
    model: str,
    camera_name: str,
    *,
    comments: Sequence[str] = (),
) -> None:
    """Write :func:`ros_camera_info_text` atomically (raises as it does, or
    :class:`InputError` for an unwritable destination)."""
    text = ros_camera_info_text(
        camera_matrix, distortion, image_size, model, camera_name, comments=comments
    )
    atomic_write_text(path, text)
