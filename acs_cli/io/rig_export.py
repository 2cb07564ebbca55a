"""Exports of a calibrated rig (``rig.yaml``): a URDF for ROS and a Kalibr camchain.

Both are pure functions from a :class:`~acs_cli.io.rig.RigArtifact` to text;
:func:`write_rig_export` writes either atomically.

URDF (:func:`urdf_from_rig`)
    The rig's kinematic tree, rooted at the reference camera's body, for
    ``robot_state_publisher``. Cameras joined by ``rigid`` edges share a body. Links:

    - ``body_<cam>``: one per rigid body, named after its first camera (in the rig's camera
      order). The root body's frame is its first camera's optical frame. Any other body's
      frame has its first camera's axes and its origin at the joint that carries it (the
      ball's centre or the hinge point), so that the URDF joint turns it about that point.
    - ``<cam>``: one per camera (its optical frame: x right, y down, z forward), fixed to its
      body. The fixed joint is named after the rigid edge that reaches the camera inside
      its body, or ``<body>_to_<cam>`` for the camera by which the body hangs from its
      parent (the reference camera for the root body).
    - ``<joint>_x_link``, ``<joint>_y_link``: the two massless links of a ball joint.

    Joints: a hinge is one ``revolute`` joint named after it, its ``<axis>`` the hinge axis
    in the child body's frame; a ball is three ``revolute`` joints ``<joint>_x``,
    ``<joint>_y``, ``<joint>_z`` about the child body's x, y and z axes, in that order
    (``R = Rx(a) Ry(b) Rz(c)``; every rotation is reachable, with a singularity at
    ``b = +-90`` degrees). At zero joint angles every camera is at its pose at the
    reference instant (``T_cam_ref``). A hinge's limits are the range of its angle over
    the calibration's frames (``angle_range_deg`` of ``rig.yaml``, in the URDF joint's own
    sense: the child turning about its ``<axis>``) widened by a margin on either side
    (:data:`DEFAULT_LIMIT_MARGIN_DEG`, ``acscal export --limit-margin``); ``[-pi, pi]`` for
    a hinge without a recorded range and for a ball's three joints. ``effort`` and
    ``velocity``, which URDF requires, are placeholders (not calibrated).

    Origins use URDF's convention: ``xyz`` then fixed-axis ``rpy`` (radians) with
    ``R = Rz(yaw) Ry(pitch) Rx(roll)``, the same as acscal's roll-pitch-yaw.

Kalibr camchain (:func:`kalibr_camchain_from_rig`; a relative pose of two cameras:
:func:`kalibr_camchain_from_pair`; both through :func:`kalibr_camchain`)
    ``cam0``, ``cam1``, ... in the rig's camera order, each with Kalibr's keys
    (``camera_model``, ``intrinsics``, ``distortion_model``, ``distortion_coeffs``,
    ``resolution``, ``rostopic``, ``cam_overlaps``) and, from ``cam1`` on, ``T_cn_cnm1``
    (4x4: maps camera n-1's frame into camera n's). For an articulated rig those transforms
    hold at the reference instant only; a YAML comment says so.

Lengths are the artifact's (``rig.length_unit``, the reference camera's units); both URDF
and Kalibr expect metres, and a comment warns when the rig's unit is another.
``acscal export`` puts them in metres first (:func:`rig_in_metres`) or refuses.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol, Union

import numpy as np
import yaml
from numpy.typing import ArrayLike

from acs_cli.core import se3
from acs_cli.core.joints import joint_model
from acs_cli.core.joints.base import UrdfJoint
from acs_cli.core.rig import RigTopology, rig_topology
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError
from acs_cli.io.artifacts import to_plain
from acs_cli.io.atomic import atomic_write_text
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.rig import RigArtifact

__all__ = [
    "RIG_EXPORT_FORMATS",
    "IntrinsicsFields",
    "IntrinsicsLike",
    "kalibr_camchain",
    "kalibr_camchain_from_pair",
    "kalibr_camchain_from_rig",
    "matrix_from_urdf_rpy",
    "rig_in_metres",
    "urdf_from_rig",
    "urdf_rpy_from_matrix",
    "write_rig_export",
]

#: The formats :func:`write_rig_export` writes.
RIG_EXPORT_FORMATS = ("kalibr", "urdf")

#: Revolute limits of the URDF joints, radians (wide: the joints are not limited).
_LIMIT = math.pi
#: Degrees added on either side of a hinge's observed range for its URDF limits.
DEFAULT_LIMIT_MARGIN_DEG = 10.0
#: Placeholders for the ``effort`` (N m) and ``velocity`` (rad/s) URDF requires.
_EFFORT = 1.0
_VELOCITY = 1.0
#: Largest ``|K[0, 1]| / fx`` (skew) and distortion term Kalibr cannot hold that is ignored.
_TINY = 1e-12


class IntrinsicsFields(Protocol):
    """What the camchain needs of a camera's intrinsics.

    :class:`acs_cli.io.intrinsics.IntrinsicsArtifact` (``intrinsics.yaml``) has these.

    Attributes
    ----------
    model : {"pinhole", "rational", "fisheye"}
    camera_matrix : array_like, shape (3, 3)
        ``K``, pixels (OpenCV convention).
    distortion : array_like
        OpenCV's order: pinhole ``k1 k2 p1 p2 k3``, rational ``k1 .. k6`` (8 numbers),
        fisheye ``k1 k2 k3 k4``.
    image_size : tuple of int
        ``(width, height)``, pixels.
    """

    @property
    def model(self) -> str: ...

    @property
    def camera_matrix(self) -> ArrayLike: ...

    @property
    def distortion(self) -> ArrayLike: ...

    @property
    def image_size(self) -> tuple[int, int]: ...


#: A camera's intrinsics: the object or the path of an ``acscal/intrinsics`` YAML file.
IntrinsicsLike = Union[IntrinsicsFields, str, "os.PathLike[str]"]


# --------------------------------------------------------------------------------------
# rotations in URDF's convention


def urdf_rpy_from_matrix(R: ArrayLike) -> tuple[float, float, float]:
    """URDF ``rpy`` (radians) of a rotation: ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.

    Stable everywhere, gimbal lock included (``pitch = +-pi/2``, where only ``yaw - roll``
    or ``yaw + roll`` is determined: yaw is then 0 when the first column is exactly
    ``[0, 0, -+1]``). :func:`matrix_from_urdf_rpy` gives
    ``R`` back to rounding (~1e-15).

    Parameters
    ----------
    R : array_like, shape (3, 3)
        A rotation matrix.

    Returns
    -------
    tuple of float
        ``(roll, pitch, yaw)``, radians; ``pitch`` in ``[-pi/2, pi/2]``.
    """
    m = np.asarray(R, dtype=float)
    c = math.hypot(m[0, 0], m[1, 0])  # |cos(pitch)|
    # yaw from the first column, however short: R's rounding errors then stay in M's
    # entries below; at exact gimbal lock (c == 0) yaw is set to 0
    yaw = math.atan2(m[1, 0], m[0, 0]) if c > 0 else 0.0
    # M = Rz(yaw)^T R = Ry(pitch) Rx(roll): its rows are well conditioned at any pitch
    cy, sy = math.cos(yaw), math.sin(yaw)
    M = np.array([[cy, sy, 0.0], [-sy, cy, 0.0], [0.0, 0.0, 1.0]]) @ m
    pitch = math.atan2(-M[2, 0], c)  # c = M[0, 0] >= 0 (up to rounding)
    roll = math.atan2(-M[1, 2], M[1, 1])
    return roll, pitch, yaw


def matrix_from_urdf_rpy(rpy: ArrayLike) -> FloatArray:
    """Rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` from URDF ``rpy`` ``(3,)`` (radians)."""
    r, p, y = (float(v) for v in np.asarray(rpy, dtype=float).reshape(3))
    cr, sr = math.cos(r), math.sin(r)
    cp, sp = math.cos(p), math.sin(p)
    cy, sy = math.cos(y), math.sin(y)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return np.asarray(Rz @ Ry @ Rx)


# --------------------------------------------------------------------------------------
# the rig's bodies


def _topology(rig: RigArtifact) -> RigTopology:
    """The rig's validated tree (InputError naming the key when it is not a tree)."""
    return rig_topology(
        rig.cameras.keys(),
        [(j.name, j.between, j.type) for j in rig.joints.values()],
        rig.reference_camera,
    )


@dataclass(frozen=True)
class _Body:
    """A rigid body of the rig: its cameras (rig order) and its frame in the reference's."""

    name: str
    cameras: tuple[str, ...]
    T_ref_body: FloatArray  # (4, 4): maps the body's frame into the reference camera's
    entry: str  # the camera by which the body hangs from its parent (or the reference)


def _T_ref_cam(rig: RigArtifact, cam: str) -> FloatArray:
    """``T_ref_cam`` (4, 4): the camera's pose in the reference camera's frame."""
    return se3.invert_transforms(rig.posed(cam))


def _bodies(
    rig: RigArtifact, topo: RigTopology
) -> tuple[dict[str, _Body], dict[str, str], list[tuple[str, str, str]]]:
    """The rig's bodies, the body of each camera, the non-rigid steps in tree order.

    Returns
    -------
    bodies : dict
        Body name to :class:`_Body`, parents before children.
    body_of : dict
        Camera name to its body's name.
    articulations : list of (joint, parent camera, child camera)
        Every ball or hinge edge, walked away from the reference camera.
    """
    order = list(rig.cameras)
    # the cameras of each body: connected components of the rigid edges
    group: dict[str, list[str]] = {c: [c] for c in order}
    for j in rig.joints.values():
        if j.model.constant_transform:
            a, b = group[j.between[0]], group[j.between[1]]
            if a is not b:
                a.extend(b)
                for c in b:
                    group[c] = a
    members = {c: sorted(group[c], key=order.index) for c in order}
    body_of = {c: f"body_{members[c][0]}" for c in order}

    ref = topo.reference
    articulations: list[tuple[str, str, str]] = []
    T_ref_body: dict[str, FloatArray] = {body_of[ref]: _T_ref_cam(rig, members[ref][0])}
    entries = {body_of[ref]: ref}
    for step in topo.tree_order():
        if joint_model(step.joint.type).constant_transform:
            continue
        j = rig.joints[step.joint.name]
        parent, child = step.source, step.target
        for key in ("position_in", "axis_in") if j.model.has_axis else ("position_in",):
            if any(c not in getattr(j, key) for c in j.between):
                raise InputError(
                    f"joints.{j.name}.{key}: needs both {j.between[0]} and {j.between[1]}"
                )
        name = body_of[child]
        # the joint point: both cameras' estimates of it, averaged in the reference frame
        point = 0.5 * (
            se3.transform_points(_T_ref_cam(rig, parent), j.position_in[parent])
            + se3.transform_points(_T_ref_cam(rig, child), j.position_in[child])
        )
        R = _T_ref_cam(rig, members[child][0])[:3, :3]
        T_ref_body[name] = se3.transforms_from_rt(R, point)
        entries[name] = child
        articulations.append((j.name, parent, child))
    bodies = {
        name: _Body(name, tuple(members[entries[name]]), T_ref_body[name], entries[name])
        for name in T_ref_body
    }
    return bodies, body_of, articulations


# --------------------------------------------------------------------------------------
# URDF


def _num(v: float) -> str:
    """A number as URDF text, exact on reading back (shortest round-trip repr)."""
    x = float(v)
    if x.is_integer() and abs(x) < 1e15:
        return str(int(x))  # "0" also for -0.0
    return repr(x)


def _origin(parent: ET.Element, T: FloatArray) -> None:
    roll, pitch, yaw = urdf_rpy_from_matrix(T[:3, :3])
    ET.SubElement(
        parent,
        "origin",
        xyz=" ".join(_num(v) for v in T[:3, 3]),
        rpy=" ".join(_num(v) for v in (roll, pitch, yaw)),
    )


class _Urdf:
    """Builds the ``<robot>`` element; refuses a link or joint name given twice."""

    def __init__(self, robot_name: str) -> None:
        self.robot = ET.Element("robot", name=robot_name)
        self.links: set[str] = set()
        self.joints: set[str] = set()

    def comment(self, text: str) -> None:
        self.robot.append(ET.Comment(" " + text.replace("--", "- -") + " "))

    def link(self, name: str) -> None:
        if name in self.links:
            raise InputError(f"URDF export: the link name {name!r} would be used twice")
        self.links.add(name)
        ET.SubElement(self.robot, "link", name=name)

    def joint(
        self,
        name: str,
        kind: str,
        parent: str,
        child: str,
        T_parent_child: FloatArray,
        axis: FloatArray | None = None,
        limit: tuple[float, float] | None = None,
    ) -> None:
        if name in self.joints:
            raise InputError(f"URDF export: the joint name {name!r} would be used twice")
        self.joints.add(name)
        el = ET.SubElement(self.robot, "joint", name=name, type=kind)
        _origin(el, T_parent_child)
        ET.SubElement(el, "parent", link=parent)
        ET.SubElement(el, "child", link=child)
        if axis is not None:
            ET.SubElement(el, "axis", xyz=" ".join(_num(v) for v in axis))
        if kind == "revolute":
            lower, upper = limit if limit is not None else (-_LIMIT, _LIMIT)
            ET.SubElement(
                el,
                "limit",
                lower=_num(lower),
                upper=_num(upper),
                effort=_num(_EFFORT),
                velocity=_num(_VELOCITY),
            )


def _hinge_axis_in_body(
    rig: RigArtifact, joint: str, parent: str, child: str, T_ref_body: FloatArray
) -> FloatArray:
    """The hinge axis (unit) in the child body's frame: both cameras' estimates, averaged."""
    j = rig.joints[joint]
    R_body_ref = T_ref_body[:3, :3].T
    axes = []
    for cam in (parent, child):
        a = np.asarray(j.axis_in[cam], dtype=float)
        n = float(np.linalg.norm(a))
        if not n > 0:
            raise InputError(f"joints.{joint}.axis_in.{cam}: the hinge axis has zero length")
        axes.append(R_body_ref @ _T_ref_cam(rig, cam)[:3, :3] @ (a / n))
    if float(axes[0] @ axes[1]) < 0:  # one axis given the other way round
        axes[0] = -axes[0]
    mean = axes[0] + axes[1]
    return np.asarray(mean / np.linalg.norm(mean))


def _hinge_limit(
    rig: RigArtifact,
    joint: str,
    parent: str,
    axis_body: FloatArray,
    T_ref_body: FloatArray,
    margin_deg: float,
) -> tuple[float, float] | None:
    """A hinge's URDF limits (rad): ``rig.yaml``'s ``angle_range_deg`` (``q`` turning
    relative to ``p`` about ``axis_in[p]``) in the URDF joint's sense (the child, hung from
    ``parent``, turning about ``axis_body``, in the child body's frame) widened by
    ``margin_deg``; None without a recorded range."""
    j = rig.joints[joint]
    if j.angle_range_deg is None:
        return None
    p = j.between[0]
    a_p = _T_ref_cam(rig, p)[:3, :3] @ np.asarray(j.axis_in[p], dtype=float)
    # reversed when the parent is q (p then turns relative to q) or the axes oppose
    sign = (1.0 if parent == p else -1.0) * float(np.sign(a_p @ (T_ref_body[:3, :3] @ axis_body)))
    lo, hi = sorted(sign * v for v in j.angle_range_deg)
    return math.radians(lo - margin_deg), math.radians(hi + margin_deg)


def urdf_from_rig(
    rig: RigArtifact,
    robot_name: str = "acs_rig",
    limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG,
) -> str:
    """The rig as a URDF (XML text) for ``robot_state_publisher``.

    See the module doc for the links, joints and frames. At zero joint angles every camera
    link ``<cam>`` is at the camera's pose at the reference instant: the transform from the
    root link to ``<cam>`` is ``T_ref_cam = inv(rig.cameras[cam].T_cam_ref)``, up to the
    root body's frame (the first camera of the reference camera's body).

    Parameters
    ----------
    rig : RigArtifact
        The calibrated rig; lengths in ``rig.length_unit`` (URDF expects metres).
    robot_name : str
        The ``<robot name>``.
    limit_margin_deg : float
        Degrees added on either side of each hinge's observed angle range for its limits.

    Returns
    -------
    str
        The URDF document, ending with a newline.

    Raises
    ------
    InputError
        The joints do not form a tree over the cameras, a hinge axis of zero length, a
        joint or link name that would be used twice, an empty ``robot_name``, a negative
        or non-finite ``limit_margin_deg``.
    """
    if not robot_name or not robot_name.strip():
        raise InputError("URDF export: the robot name must not be empty")
    if not (math.isfinite(limit_margin_deg) and limit_margin_deg >= 0):
        raise InputError(
            f"URDF export: the limits' margin must be a non-negative number of degrees, got "
            f"{limit_margin_deg:g}"
        )
    topo = _topology(rig)
    bodies, body_of, articulations = _bodies(rig, topo)
    u = _Urdf(robot_name)
    ref, frame = rig.reference_camera, rig.reference_frame
    root = body_of[ref]
    u.comment(
        f"Articulated camera rig calibrated by acscal: {len(rig.cameras)} cameras, "
        f"{len(rig.joints)} joints. Root link {root} (the body of the reference camera "
        f"{ref}). At zero joint angles every camera link is at its pose at the reference "
        f"instant (frame {frame})."
    )
    u.comment(
        "Camera links are optical frames (x right, y down, z forward). A body link has its "
        "first camera's axes; its origin is that camera's centre for the root body and the "
        "joint that carries it for any other body."
    )
    if rig.length_unit != "m":
        u.comment(
            f"WARNING: lengths are in {rig.length_unit} (the reference camera's trajectory "
            "units), not metres as URDF expects."
        )
    else:
        u.comment("Lengths in metres, angles in radians.")
    if articulations:
        u.comment(
            "A hinge's limits are the range of its angle over the calibration's frames (as "
            f"rig.yaml records it), widened by {_num(limit_margin_deg)} deg on either side; "
            "other revolute limits "
            f"are [-pi, pi]. Effort ({_num(_EFFORT)}) and velocity ({_num(_VELOCITY)}) are "
            "placeholders URDF requires, not calibrated values."
        )

    # links: bodies (parents first), cameras, the massless links of ball joints
    for body in bodies.values():
        u.link(body.name)
    for cam in rig.cameras:
        u.link(cam)
    # each articulation as its type's model maps it (JointModel.urdf)
    urdf: dict[str, tuple[list[str], list[UrdfJoint], str]] = {}
    for name, parent, child in articulations:
        j = rig.joints[name]
        P, C = bodies[body_of[parent]], bodies[body_of[child]]
        T_P_C = se3.invert_transforms(P.T_ref_body) @ C.T_ref_body
        axis = (
            _hinge_axis_in_body(rig, name, parent, child, C.T_ref_body)
            if j.model.has_axis
            else None
        )
        links, joints, comment = j.model.urdf(topo.joint(name), P.name, C.name, T_P_C, axis)
        if axis is not None:
            limit = _hinge_limit(rig, name, parent, axis, C.T_ref_body, limit_margin_deg)
            joints = [replace(uj, limit=limit) for uj in joints]
        urdf[name] = (links, joints, comment)
    for name, (links, _, _) in urdf.items():
        if links:
            u.comment(f"massless intermediate links of the {rig.joints[name].type} joint {name}")
        for link in links:
            u.link(link)

    # cameras fixed to their bodies; the fixed joint is named after the rigid edge
    rigid_to: dict[str, str] = {}
    for step in topo.tree_order():
        if joint_model(step.joint.type).constant_transform:
            rigid_to[step.target] = step.joint.name
    for body in bodies.values():
        for cam in body.cameras:
            T_ref_cam = _T_ref_cam(rig, cam)
            if cam == body.cameras[0]:  # the body has this camera's axes: keep them exact
                R_ref_body, t_ref_body = body.T_ref_body[:3, :3], body.T_ref_body[:3, 3]
                T_body_cam = se3.transforms_from_rt(
                    np.eye(3), R_ref_body.T @ (T_ref_cam[:3, 3] - t_ref_body)
                )
            else:
                T_body_cam = se3.invert_transforms(body.T_ref_body) @ T_ref_cam
            if cam in rigid_to:
                j = rig.joints[rigid_to[cam]]
                u.comment(
                    f"rigid edge {j.name} ({j.between[0]}-{j.between[1]}): {cam} fixed on "
                    f"{body.name}"
                )
                u.joint(j.name, "fixed", body.name, cam, T_body_cam)
            else:
                u.joint(f"{body.name}_to_{cam}", "fixed", body.name, cam, T_body_cam)

    # articulations, parents before children
    for _links, joints, comment in urdf.values():
        u.comment(comment)
        for uj in joints:
            u.joint(uj.name, uj.type, uj.parent, uj.child, uj.origin, uj.axis, uj.limit)

    ET.indent(u.robot, space="  ")
    return '<?xml version="1.0"?>\n' + ET.tostring(u.robot, encoding="unicode") + "\n"


# --------------------------------------------------------------------------------------
# Kalibr camchain


def _read_intrinsics(value: IntrinsicsLike) -> IntrinsicsFields:
    if isinstance(value, (str, os.PathLike)):
        return IntrinsicsArtifact.load(Path(value))
    return value


def _kalibr_intrinsics(cam: str, value: IntrinsicsLike) -> dict[str, Any]:
    """Kalibr's ``camera_model`` .. ``resolution`` of one camera from acscal's intrinsics."""
    intr = _read_intrinsics(value)
    where = f"camera {cam}"
    K = np.asarray(intr.camera_matrix, dtype=float)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or not (K[0, 0] > 0 and K[1, 1] > 0):
        raise InputError(f"{where}: the camera matrix must be a finite 3x3 K with fx, fy > 0")
    if abs(K[0, 1]) > _TINY * K[0, 0]:
        raise InputError(f"{where}: Kalibr's pinhole model has no skew (K[0, 1] = {K[0, 1]:g})")
    D = np.asarray(intr.distortion, dtype=float).ravel()
    model = str(intr.model)
    if model == "fisheye":
        if D.size != 4:
            raise InputError(f"{where}: a fisheye model needs 4 distortion coefficients")
        dist_model, coeffs = "equidistant", D
    elif model in ("pinhole", "rational"):
        n = 5 if model == "pinhole" else 8
        if D.size != n:
            raise InputError(f"{where}: the {model} model needs {n} distortion coefficients")
        extra = D[4:]
        if np.any(np.abs(extra) > _TINY):
            raise InputError(
                f"{where}: Kalibr's radtan model holds k1 k2 p1 p2 only; this {model} "
                f"calibration has non-zero higher terms ({', '.join(f'{v:g}' for v in extra)}). "
                "Calibrate the camera with the pinhole model (k3 held at 0)"
            )
        dist_model, coeffs = "radtan", D[:4]
    else:
        raise InputError(f"{where}: unknown camera model {model!r}")
    if not np.all(np.isfinite(coeffs)):
        raise InputError(f"{where}: the distortion coefficients must be finite")
    size = np.asarray(intr.image_size).ravel()
    if size.shape != (2,) or np.any(size <= 0) or np.any(size != np.round(size)):
        raise InputError(f"{where}: the image size must be [width, height] in pixels")
    return {
        "camera_model": "pinhole",
        "intrinsics": [float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])],
        "distortion_model": dist_model,
        "distortion_coeffs": [float(v) for v in coeffs],
        "resolution": [int(size[0]), int(size[1])],
    }


def _overlap_indices(
    cams: Sequence[str], overlaps: Mapping[str, Iterable[str]] | None
) -> dict[str, list[int]]:
    """Symmetric ``cam_overlaps`` (indices) from camera names."""
    out: dict[str, set[int]] = {c: set() for c in cams}
    for cam, others in (overlaps or {}).items():
        for name in (cam, *others):
            if name not in out:
                raise InputError(
                    f"cam_overlaps: unknown camera {name!r}; the rig has {', '.join(cams)}"
                )
        for other in others:
            if other != cam:
                out[cam].add(cams.index(other))
                out[other].add(cams.index(cam))
    return {c: sorted(v) for c, v in out.items()}


def _yaml_block(doc: Mapping[str, Any]) -> str:
    return yaml.safe_dump(to_plain(doc), sort_keys=False, default_flow_style=None)


def kalibr_camchain(
    cameras: Sequence[str],
    T_cn_cnm1: Sequence[ArrayLike | None],
    intrinsics: Mapping[str, IntrinsicsLike] | None,
    *,
    header: Sequence[str] = (),
    comments: Sequence[str] | None = None,
    overlaps: Mapping[str, Iterable[str]] | None = None,
) -> str:
    """A Kalibr camchain YAML of a chain of cameras (``cam0``, ``cam1``, ... in order).

    Each ``camN`` holds ``camera_model: pinhole``, ``intrinsics: [fu, fv, pu, pv]`` (px),
    ``distortion_model`` (``radtan`` ``[k1, k2, p1, p2]`` for acscal's pinhole model and a
    rational one whose k3..k6 are 0, ``equidistant`` ``[k1, k2, k3, k4]`` for its fisheye
    model), ``distortion_coeffs``, ``resolution: [width, height]``, ``rostopic``
    (``/<camera>/image_raw``) and ``cam_overlaps`` (indices); from ``cam1`` on,
    ``T_cn_cnm1`` (4x4, maps camera n-1's frame into camera n's: Kalibr's
    ``T_cn_cnm1 = T_c1_c0`` for ``cam1``), the fields and types Kalibr's
    ``CameraChainParameters`` reads.

    Parameters
    ----------
    cameras : sequence of str
        The cameras' names, in chain order.
    T_cn_cnm1 : sequence of (4, 4) array_like or None
        One per camera: ``None`` for the first, ``T_<n>_<n-1>`` for the others (lengths as
        they are: Kalibr expects metres).
    intrinsics : mapping of camera name to intrinsics, or None
        Every camera's intrinsics: an object with ``model``, ``camera_matrix``,
        ``distortion`` and ``image_size`` (an
        :class:`~acs_cli.io.intrinsics.IntrinsicsArtifact`), or the path of an
        ``acscal/intrinsics`` YAML file (read with ``IntrinsicsArtifact.load``).
    header : sequence of str
        Comment lines at the top (without ``#``).
    comments : sequence of str, optional
        One comment line (without ``#``) before each camera; ``camN: <name>`` without.
    overlaps : mapping of camera name to camera names, optional
        Cameras that share views (made symmetric); ``cam_overlaps: []`` without.

    Returns
    -------
    str
        The camchain YAML.

    Raises
    ------
    InputError
        A camera without intrinsics (Kalibr refuses such a camchain; the message names
        every such camera), intrinsics of an unknown camera, intrinsics Kalibr cannot hold
        (rational with non-zero k3..k6, pinhole with k3, skew), unreadable intrinsics files,
        unknown cameras in ``overlaps``, a ``T_cn_cnm1`` that is not
        rigid (or given for the first camera, or missing for another).
    ValueError
        ``T_cn_cnm1`` or ``comments`` not one per camera.
    """
    cams = list(cameras)
    if len(T_cn_cnm1) != len(cams) or (comments is not None and len(comments) != len(cams)):
        raise ValueError("T_cn_cnm1 and comments need one entry per camera")
    given = dict(intrinsics or {})
    unknown = [c for c in given if c not in cams]
    if unknown:
        raise InputError(
            f"intrinsics given for {', '.join(map(str, unknown))}, not a camera of the rig "
            f"({', '.join(cams)})"
        )
    missing = [c for c in cams if c not in given or given[c] is None]
    if missing:
        raise InputError(
            "Kalibr needs every camera's intrinsics; missing for "
            + ", ".join(missing)
            + " (give each camera's intrinsics.yaml)"
        )
    overlap = _overlap_indices(cams, overlaps)
    text = "".join(f"# {line}\n" for line in header)
    for i, cam in enumerate(cams):
        entry: dict[str, Any] = {}
        T = T_cn_cnm1[i]
        if (T is None) != (i == 0):
            raise InputError(f"camera {cam}: T_cn_cnm1 is for every camera but the first")
        if T is not None:
            entry["T_cn_cnm1"] = se3.check_transforms(T, name=f"camera {cam} T_cn_cnm1")[0]
        entry.update(_kalibr_intrinsics(cam, given[cam]))
        entry["rostopic"] = f"/{cam}/image_raw"
        entry["cam_overlaps"] = overlap[cam]
        comment = f"cam{i}: {cam}" if comments is None else comments[i]
        text += f"# {comment}\n" + _yaml_block({f"cam{i}": entry})
    return text


def kalibr_camchain_from_rig(
    rig: RigArtifact,
    intrinsics: Mapping[str, IntrinsicsLike] | None,
    *,
    notes: Sequence[str] = (),
) -> str:
    """The rig as a Kalibr camchain YAML (:func:`kalibr_camchain`, in the rig's camera order).

    ``T_cn_cnm1`` is ``T_<n>_<n-1>`` at the reference instant, in ``rig.length_unit`` (a
    comment warns when that is not metres). A comment before each camera names it and
    the ball or hinge joints between it and the previous camera, whose ``T_cn_cnm1`` then
    holds at the reference instant only.

    Parameters
    ----------
    rig : RigArtifact
        The calibrated rig.
    intrinsics
        As :func:`kalibr_camchain`.
    notes : sequence of str
        More comment lines for the top (e.g. where the intrinsics came from, warnings).

    Returns
    -------
    str
        The camchain YAML.

    Raises
    ------
    InputError
        What :func:`kalibr_camchain` raises, and joints that do not form a tree.
    """
    topo = _topology(rig)
    cams = list(rig.cameras)
    header = [
        "Kalibr camchain exported by acscal from a calibrated rig",
        f"cameras in the rig's order: {', '.join(f'cam{i} = {c}' for i, c in enumerate(cams))}",
        "T_cn_cnm1 maps camera n-1's frame into camera n's (p_n = T_cn_cnm1 p_nm1), "
        f"lengths in {'metres' if rig.length_unit == 'm' else rig.length_unit}",
    ]
    if rig.length_unit != "m":
        header.append(f"WARNING: Kalibr expects metres; these lengths are in {rig.length_unit}")
    articulated = [j for j in rig.joints.values() if not j.model.constant_transform]
    if articulated:
        header += [
            "The rig is articulated ("
            + ", ".join(f"{j.name}: {j.type}" for j in articulated)
            + "): a T_cn_cnm1 across such a joint",
            f"holds at the reference instant only (frame {rig.reference_frame} of "
            f"{rig.reference_camera}'s trajectory); Kalibr takes it as fixed.",
        ]
    comments: list[str] = []
    transforms: list[FloatArray | None] = []
    for i, cam in enumerate(cams):
        comment = f"cam{i}: {cam}"
        if i > 0:
            prev = cams[i - 1]
            moving = [
                s.joint
                for s in topo.path(prev, cam)
                if not joint_model(s.joint.type).constant_transform
            ]
            if moving:
                comment += (
                    f"; T_cn_cnm1 from {prev} across "
                    + ", ".join(f"{j.name} ({j.type})" for j in moving)
                    + ": at the reference instant only"
                )
            else:
                comment += f"; rigidly mounted with {prev}"
        comments.append(comment)
        transforms.append(rig.T_a_b(cam, cams[i - 1]) if i > 0 else None)
    return kalibr_camchain(
        cams,
        transforms,
        intrinsics,
        header=[*header, *notes],
        comments=comments,
    )


def kalibr_camchain_from_pair(
    T_b_a: ArrayLike,
    intrinsics: Mapping[str, IntrinsicsLike] | None,
    *,
    names: tuple[str, str] = ("cam_a", "cam_b"),
    reference: int = 0,
    overlap: bool = False,
    notes: Sequence[str] = (),
) -> str:
    """Two cameras joined by a joint (``relpose.yaml``) as a Kalibr camchain.

    ``cam0`` is camera A, ``cam1`` camera B with ``T_cn_cnm1 = T_b_a`` (maps A's frame into
    B's), which holds at the reference instant only: a comment says so.

    Parameters
    ----------
    T_b_a : array_like, shape (4, 4)
        The relative pose at the reference instant, metres.
    intrinsics : mapping, or None
        Both cameras' intrinsics, by the names in ``names`` (as :func:`kalibr_camchain`).
    names : tuple of str
        The cameras' names (their default topics ``/<name>/image_raw``).
    reference : int
        The reference instant (paired frame) ``T_b_a`` holds at.
    overlap : bool
        Whether the cameras share views (``cam_overlaps`` ``[1]`` and ``[0]``).
    notes : sequence of str
        More comment lines for the top.

    Returns
    -------
    str
        The camchain YAML.

    Raises
    ------
    InputError
        What :func:`kalibr_camchain` raises.
    """
    a, b = names
    header = [
        "Kalibr camchain exported by acscal from a relative pose (relpose.yaml)",
        f"cam0 = {a} (camera A), cam1 = {b} (camera B)",
        "T_cn_cnm1 of cam1 is T_b_a: maps camera A's frame into camera B's "
        "(p_b = T_cn_cnm1 p_a), metres.",
        f"The cameras are joined by an articulated joint: T_cn_cnm1 holds at the reference "
        f"instant only (paired frame {reference}); Kalibr takes it as fixed.",
    ]
    return kalibr_camchain(
        [a, b],
        [None, T_b_a],
        intrinsics,
        header=[*header, *notes],
        comments=[f"cam0: {a}", f"cam1: {b}; T_cn_cnm1 = T_b_a at the reference instant only"],
        overlaps={a: [b]} if overlap else None,
    )


def rig_in_metres(rig: RigArtifact, metres_per_unit: float) -> RigArtifact:
    """The rig with every length multiplied by ``metres_per_unit`` (``length_unit: m``).

    Scales each camera's ``T_cam_ref`` and ``T_ref_world`` translations and their stds,
    and each joint's positions, their stds and ``residual_rms``; rotations, axes and the
    cameras' ``scale`` (a ratio of trajectory units) are unchanged.

    Raises
    ------
    ValueError
        A factor that is not a positive finite number.
    """
    s = float(metres_per_unit)
    if not (math.isfinite(s) and s > 0):
        raise ValueError(f"metres_per_unit must be positive and finite, got {metres_per_unit}")

    def scaled(T: FloatArray) -> FloatArray:
        out = np.array(T, dtype=float)
        out[:3, 3] *= s
        return out

    cameras = {
        name: replace(
            c,
            T_cam_ref=None if c.T_cam_ref is None else scaled(c.T_cam_ref),
            translation_std=np.asarray(c.translation_std, dtype=float) * s,
            T_ref_world=None if c.T_ref_world is None else scaled(c.T_ref_world),
        )
        for name, c in rig.cameras.items()
    }
    joints = {
        name: replace(
            j,
            position_in={k: np.asarray(v, dtype=float) * s for k, v in j.position_in.items()},
            position_std_in={
                k: np.asarray(v, dtype=float) * s for k, v in j.position_std_in.items()
            },
            residual_rms=j.residual_rms * s,
        )
        for name, j in rig.joints.items()
    }
    return replace(rig, cameras=cameras, joints=joints, length_unit="m")


# --------------------------------------------------------------------------------------
# writing


def _xml_comment(text: str) -> str:
    """``text`` on one line, safe inside an XML comment (no ``--``)."""
    return " ".join(str(text).split()).replace("--", "- -")


def write_rig_export(
    path: str | os.PathLike[str],
    rig: RigArtifact,
    fmt: str,
    *,
    intrinsics: Mapping[str, IntrinsicsLike] | None = None,
    robot_name: str = "acs_rig",
    notes: Sequence[str] = (),
    limit_margin_deg: float = DEFAULT_LIMIT_MARGIN_DEG,
) -> str:
    """Write the rig as ``fmt`` (``"urdf"`` or ``"kalibr"``) atomically.

    Parameters
    ----------
    path : path
        The destination file.
    rig : RigArtifact
    fmt : {"urdf", "kalibr"}
    intrinsics : mapping, optional
        Every camera's intrinsics (required by ``kalibr``), as for
        :func:`kalibr_camchain_from_rig`.
    robot_name : str
        ``urdf``: the robot's name.
    notes : sequence of str
        Comment lines for the top of the file (after its own).
    limit_margin_deg : float
        ``urdf``: degrees added on either side of each hinge's observed angle range.

    Returns
    -------
    str
        The text written.

    Raises
    ------
    InputError
        An unknown format, what the chosen export raises, an unwritable destination.
    """
    if fmt == "urdf":
        text = urdf_from_rig(rig, robot_name=robot_name, limit_margin_deg=limit_margin_deg)
        if notes:
            head, sep, rest = text.partition("\n")
            text = head + sep + "".join(f"<!-- {_xml_comment(n)} -->\n" for n in notes) + rest
    elif fmt == "kalibr":
        text = kalibr_camchain_from_rig(rig, intrinsics, notes=notes)
    else:
        raise InputError(
            f"unknown rig export format {fmt!r}; use one of {', '.join(RIG_EXPORT_FORMATS)}"
        )
    atomic_write_text(Path(path), text)
    return text
