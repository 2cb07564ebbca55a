"""A hand-eye calibration as ROS loads it: easy_handeye's YAML and ``static_transform_publisher``.

easy_handeye (``~/.ros/easy_handeye/<namespace>.yaml``, read by its ``publish.launch``) keeps
``parameters`` (the frames, ``eye_on_hand``) and ``transformation`` (``x y z qx qy qz qw``):
for an eye-in-hand calibration the camera's pose in the robot's effector frame
(``robot_effector_frame`` the parent, ``tracking_base_frame`` the child: tf's
``T_parent_child``, which maps the child's points into the parent). acscal adds its own key,
``acscal``, which easy_handeye ignores: the transform's std, the board in the robot's base
frame (eye-in-hand's other unknown) with its std, and the ``static_transform_publisher``
command lines (ROS 1 and ROS 2) that publish both.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from acs_cli.core import se3
from acs_cli.core.se3 import FloatArray
from acs_cli.io.atomic import atomic_path

__all__ = ["HandEyeExport", "static_transform_lines", "write_handeye"]


@dataclass(frozen=True)
class HandEyeExport:
    """What :func:`write_handeye` writes; lengths in metres.

    Attributes
    ----------
    T_effector_camera : ndarray, shape (4, 4)
        The camera's pose in the robot's effector (flange) frame.
    std : (rotation_deg (3,), translation (3,)) or None
        Its std (right rotation perturbation, then translation).
    T_base_board : ndarray (4, 4) or None
        The board in the robot's base frame, with ``board_std`` like ``std``.
    base_frame, effector_frame, camera_frame, board_frame : str
        The tf frame names.
    namespace : str
        easy_handeye's namespace (its file name).
    """

    T_effector_camera: FloatArray
    std: tuple[FloatArray, FloatArray] | None
    T_base_board: FloatArray | None
    board_std: tuple[FloatArray, FloatArray] | None
    base_frame: str
    effector_frame: str
    camera_frame: str
    board_frame: str
    namespace: str


def _xyzq(T: FloatArray) -> dict[str, float]:
    q = se3.quat_xyzw_from_matrix(np.asarray(T, dtype=float)[:3, :3])
    t = np.asarray(T, dtype=float)[:3, 3]
    return {
        "x": float(t[0]), "y": float(t[1]), "z": float(t[2]),
        "qx": float(q[0]), "qy": float(q[1]), "qz": float(q[2]), "qw": float(q[3]),
    }  # fmt: skip


def static_transform_lines(T: FloatArray, parent: str, child: str) -> tuple[str, str]:
    """The ROS 1 and ROS 2 ``static_transform_publisher`` commands publishing ``T`` (the
    child's pose in the parent, metres) from ``parent`` to ``child``."""
    p = _xyzq(T)
    nums = " ".join(f"{p[k]:.9g}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw"))
    ros1 = f"rosrun tf2_ros static_transform_publisher {nums} {parent} {child}"
    flags = " ".join(f"--{k} {p[k]:.9g}" for k in ("x", "y", "z", "qx", "qy", "qz", "qw"))
    ros2 = (
        f"ros2 run tf2_ros static_transform_publisher {flags} "
        f"--frame-id {parent} --child-frame-id {child}"
    )
    return ros1, ros2


def _std(s: tuple[FloatArray, FloatArray] | None) -> dict[str, list[float]] | None:
    if s is None:
        return None
    return {"rotation_deg": [float(v) for v in s[0]], "translation_m": [float(v) for v in s[1]]}


def write_handeye(path: str | Path, he: HandEyeExport, notes: list[str]) -> dict[str, Any]:
    """Write easy_handeye's YAML (module doc) atomically, ``notes`` as comments on top;
    return what was written."""
    lines = {
        "camera": static_transform_lines(he.T_effector_camera, he.effector_frame, he.camera_frame)
    }
    if he.T_base_board is not None:
        lines["board"] = static_transform_lines(he.T_base_board, he.base_frame, he.board_frame)
    doc: dict[str, Any] = {
        "parameters": {
            "eye_on_hand": True,
            "freehand_robot_movement": True,
            "move_group": "manipulator",
            "move_group_namespace": "/",
            "namespace": f"/{he.namespace}/",
            "robot_base_frame": he.base_frame,
            "robot_effector_frame": he.effector_frame,
            "tracking_base_frame": he.camera_frame,
            "tracking_marker_frame": he.board_frame,
        },
        "transformation": _xyzq(he.T_effector_camera),
        "acscal": {
            "transformation_std": _std(he.std),
            "board_in_robot_base": None if he.T_base_board is None else _xyzq(he.T_base_board),
            "board_in_robot_base_std": _std(he.board_std),
            "static_transform_publisher": {
                "ros1": [v[0] for v in lines.values()],
                "ros2": [v[1] for v in lines.values()],
            },
        },
    }
    head = "".join(f"# {n}\n" for n in notes)
    head += "".join(f"# {v[0]}\n" for v in lines.values())
    with atomic_path(path) as tmp:
        tmp.write_text(head + yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return doc
