"""The export stage: ``acscal export`` writes a calibration for other tools."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.errors import InputError
from acs_cli.io.artifacts import get_path, read_yaml_artifact
from acs_cli.io.atomic import check_distinct_output
from acs_cli.io.export import write_camchain_yaml, write_opencv_yaml

EXPORT_FORMATS = ("kalibr", "opencv")


def _matrix(doc: dict[str, Any], key: str, shape: tuple[int, ...], path: Path) -> np.ndarray:
    value = get_path(doc, key, source=path)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != shape or not np.all(np.isfinite(arr)):
        raise InputError(f"{key} must be a finite {'x'.join(map(str, shape))} array", path=path)
    return arr


def _number(doc: dict[str, Any], key: str, default: Any, path: Path, integer: bool = False) -> Any:
    """A finite number (an int32 when ``integer``) at a dotted key, else an InputError."""
    value = get_path(doc, key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        ok = False
    elif isinstance(value, int):
        ok = abs(value) < (2**31 if integer else 10**300)
    else:
        ok = bool(np.isfinite(value)) and (
            not integer or (value.is_integer() and abs(value) < 2**31)
        )
    if not ok:
        kind = "an integer" if integer else "a finite number"
        raise InputError(f"{key} must be {kind}, got {str(value)[:40]!r}", path=path)
    return int(value) if integer else float(value)


def run_export(relpose: Path, output: Path, fmt: str) -> dict[str, Any]:
    """Export ``relpose.yaml`` as a Kalibr camchain or an OpenCV FileStorage YAML.

    Returns
    -------
    dict
        What was written (``format``, ``output``, ``keys``).
    """
    if fmt not in EXPORT_FORMATS:
        raise InputError(f"unknown export format {fmt!r}; use one of {', '.join(EXPORT_FORMATS)}")
    check_distinct_output(output, [relpose])
    doc = read_yaml_artifact(relpose, "relpose", ["relative_pose.T_b_a"])
    T_b_a = _matrix(doc, "relative_pose.T_b_a", (4, 4), relpose)
    from acs_cli.core import se3  # here: scipy's import is slow

    try:
        se3.check_transforms(T_b_a, name="relative_pose.T_b_a")
    except InputError as exc:
        raise InputError(exc.message, path=relpose) from exc
    if fmt == "kalibr":
        write_camchain_yaml(output, [{"name": "cam_a"}, {"name": "cam_b", "T_cn_cnm1": T_b_a}])
        return {"format": fmt, "output": str(output), "keys": ["cam0", "cam1"]}
    mats: dict[str, Any] = {
        "T_b_a": T_b_a,
        "R_b_a": T_b_a[:3, :3],
        "t_b_a": T_b_a[:3, 3:4],
        "reference": _number(doc, "relative_pose.reference", 0, relpose, integer=True),
    }
    for which in ("a", "b"):
        pos = get_path(doc, f"joint.position_in_{which}", None)
        if pos is not None:
            mats[f"joint_in_{which}"] = _matrix(doc, f"joint.position_in_{which}", (3,), relpose)[
                :, None
            ]
    if get_path(doc, "scale.phi_ba", None) is not None:
        mats["phi_ba"] = _number(doc, "scale.phi_ba", None, relpose)
    units = get_path(doc, "units.length", "m")
    mats["length_unit"] = str(units)
    write_opencv_yaml(output, mats)
    return {"format": fmt, "output": str(output), "keys": list(mats)}
