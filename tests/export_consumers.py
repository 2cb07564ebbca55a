"""The readers of acscal's exports, as their consumers check them (shared by the tests).

- :func:`read_kalibr_camchain`: Kalibr's ``CameraChainParameters`` / ``CameraParameters``
  (``kalibr_common/ConfigReader.py``) reimplemented from its source and its documented
  format (wiki "YAML formats"): for every ``camN``, ``camera_model`` and ``intrinsics``
  (``getIntrinsics``), ``distortion_model`` and ``distortion_coeffs`` (``getDistortion``),
  ``resolution`` (``getResolution``), ``rostopic`` (``getRosTopic``), ``cam_overlaps``
  (``getCamOverlaps``) and, from ``cam1`` on, ``T_cn_cnm1`` (``getExtrinsicsLastCamToHere``:
  an ``sm.Transformation``, a 4x4 rigid transform, ``T_c1_c0`` taking cam0's coordinates to
  cam1's). A missing field is Kalibr's "Field ... missing".
- :func:`read_ros_camera_info`: camera_calibration_parsers' YAML and the
  ``sensor_msgs/CameraInfo`` message it fills (``K`` 9, ``R`` 9, ``P`` 12 numbers, ``D`` as
  many as ``distortion_model`` has: ``plumb_bob`` 5, ``rational_polynomial`` 8,
  ``equidistant`` 4), with ``camera_info_manager``'s rule for camera names.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import yaml

#: Kalibr's camera models and their number of intrinsics.
KALIBR_CAMERA_MODELS = {"pinhole": 4, "omni": 5, "ds": 6}
#: Kalibr's distortion models and their number of coefficients.
KALIBR_DISTORTION_MODELS = {"radtan": 4, "equidistant": 4, "fov": 1, "none": 0}
#: sensor_msgs/distortion_models.h and the length of ``D`` for each.
ROS_DISTORTION_MODELS = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}


class ConsumerError(RuntimeError):
    """What the consumer would refuse the file with."""


def _kalibr_camera(cam: dict[str, Any], name: str, n: int) -> dict[str, Any]:
    """One camera as Kalibr's ``CameraParameters`` getters check it."""
    if not isinstance(cam, dict):
        raise ConsumerError(f"[CameraChainParameters Reader]: {name} is not a mapping")
    for field in ("camera_model", "intrinsics", "distortion_model", "distortion_coeffs"):
        if field not in cam:
            raise ConsumerError(f"Field '{field}' missing in file")
    for field in ("resolution", "rostopic", "cam_overlaps"):
        if field not in cam:
            raise ConsumerError(f"Field '{field}' missing in file")
    model, intr = cam["camera_model"], cam["intrinsics"]
    if model not in KALIBR_CAMERA_MODELS:
        raise ConsumerError(f"Unknown camera model '{model}'")
    if not isinstance(intr, list) or len(intr) != KALIBR_CAMERA_MODELS[model]:
        raise ConsumerError(f"invalid intrinsics for {model}")
    focal, principal = intr[-4:-2], intr[-2:]
    if not all(isinstance(v, float) and v >= 0.0 for v in focal):
        raise ConsumerError("invalid focalLength (2 floats)")
    if not all(isinstance(v, float) and v >= 0.0 for v in principal):
        raise ConsumerError("invalid principalPoint")
    dist, coeffs = cam["distortion_model"], cam["distortion_coeffs"]
    if dist not in KALIBR_DISTORTION_MODELS:
        raise ConsumerError(f"Unknown distortion model '{dist}'")
    if not isinstance(coeffs, list) or len(coeffs) != KALIBR_DISTORTION_MODELS[dist]:
        raise ConsumerError(f"distortion model '{dist}' requires {KALIBR_DISTORTION_MODELS[dist]}")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in coeffs):
        raise ConsumerError("distortion_coeffs must be numbers")
    res = cam["resolution"]
    if not (isinstance(res, list) and len(res) == 2 and all(type(v) is int for v in res)):
        raise ConsumerError("invalid resolution")
    if not isinstance(cam["rostopic"], str):
        raise ConsumerError("rostopic has to be a string")
    overlaps = cam["cam_overlaps"]
    if not isinstance(overlaps, list) or not all(type(k) is int and 0 <= k < n for k in overlaps):
        raise ConsumerError("out-of-range: camera id in cam_overlaps")
    return cam


def _kalibr_transform(value: Any, name: str) -> np.ndarray:
    """``T_cn_cnm1`` as ``sm.Transformation`` takes it: a 4x4 rigid transform."""
    try:
        T = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConsumerError(f"invalid camera baseline ({name})") from exc
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ConsumerError(f"invalid camera baseline ({name})")
    R = T[:3, :3]
    if (
        not np.allclose(T[3], [0, 0, 0, 1], atol=1e-12)
        or not np.allclose(R.T @ R, np.eye(3), atol=1e-9)
        or np.linalg.det(R) < 0
    ):
        raise ConsumerError(f"invalid camera baseline ({name}): not a rigid transform")
    return T


def read_kalibr_camchain(path: str | Path) -> list[dict[str, Any]]:
    """Load a camchain as Kalibr does (``yaml.safe_load``) and check it
    (:func:`check_kalibr_camchain`)."""
    with open(path, encoding="utf-8") as f:
        return check_kalibr_camchain(yaml.safe_load(f))


def check_kalibr_camchain(doc: Any) -> list[dict[str, Any]]:
    """Check a parsed camchain camera by camera, as Kalibr's getters do.

    Returns
    -------
    list of dict
        The cameras in order, each with ``T_cn_cnm1`` as an ndarray from ``cam1`` on.

    Raises
    ------
    ConsumerError
        What Kalibr would refuse.
    """
    if not isinstance(doc, dict) or not doc:
        raise ConsumerError("Could not read configuration")
    n = len(doc)
    if sorted(doc) != sorted(f"cam{i}" for i in range(n)):
        raise ConsumerError(f"cameras must be cam0..cam{n - 1}, got {list(doc)}")
    cams = []
    for i in range(n):
        cam = dict(_kalibr_camera(doc[f"cam{i}"], f"cam{i}", n))
        if i > 0:
            if "T_cn_cnm1" not in cam:
                raise ConsumerError("Field 'T_cn_cnm1' missing in file")
            cam["T_cn_cnm1"] = _kalibr_transform(cam["T_cn_cnm1"], f"cam{i}")
        cams.append(cam)
    return cams


def _ros_matrix(doc: dict[str, Any], key: str, rows: int, cols: int | None) -> np.ndarray:
    """A ``{rows, cols, data}`` matrix as camera_calibration_parsers reads it."""
    m = doc.get(key)
    if not isinstance(m, dict) or set(m) != {"rows", "cols", "data"}:
        raise ConsumerError(f"{key}: needs rows, cols and data")
    if m["rows"] != rows or (cols is not None and m["cols"] != cols):
        raise ConsumerError(f"{key}: {m['rows']}x{m['cols']}, expected {rows}x{cols}")
    data = m["data"]
    if not isinstance(data, list) or len(data) != m["rows"] * m["cols"]:
        raise ConsumerError(f"{key}: data has not rows x cols numbers")
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in data):
        raise ConsumerError(f"{key}: data must be numbers")
    return np.array(data, dtype=float)


def read_ros_camera_info(path: str | Path) -> dict[str, Any]:
    """Load a camera_info YAML into ``sensor_msgs/CameraInfo``'s fields, checking sizes.

    Returns
    -------
    dict
        ``width``, ``height``, ``camera_name``, ``distortion_model``, ``D``, ``K``, ``R``,
        ``P`` (flat ndarrays, as in the message).

    Raises
    ------
    ConsumerError
        What camera_calibration_parsers or camera_info_manager would refuse.
    """
    with open(path, encoding="utf-8") as f:
        doc = yaml.safe_load(f)
    if not isinstance(doc, dict):
        raise ConsumerError("not a mapping")
    for key in ("image_width", "image_height"):
        if type(doc.get(key)) is not int or doc[key] <= 0:
            raise ConsumerError(f"{key} must be a positive integer (uint32)")
    name = doc.get("camera_name")
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_]+", name):
        raise ConsumerError(f"camera_name {name!r}: letters, digits and underscores")
    model = doc.get("distortion_model")
    if model not in ROS_DISTORTION_MODELS:
        raise ConsumerError(f"unknown distortion_model {model!r}")
    D = _ros_matrix(doc, "distortion_coefficients", 1, None)
    if D.size != ROS_DISTORTION_MODELS[model]:
        raise ConsumerError(f"{model} has {ROS_DISTORTION_MODELS[model]} coefficients, D {D.size}")
    return {
        "width": doc["image_width"],
        "height": doc["image_height"],
        "camera_name": name,
        "distortion_model": model,
        "D": D,
        "K": _ros_matrix(doc, "camera_matrix", 3, 3),
        "R": _ros_matrix(doc, "rectification_matrix", 3, 3),
        "P": _ros_matrix(doc, "projection_matrix", 3, 4),
    }
