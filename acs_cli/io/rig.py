"""The rig artifact: ``rig.yaml``, every camera's pose and every joint of a calibrated rig.

Keys (besides the header of :func:`acs_cli.io.artifacts.make_header`)::

    reference: {camera: cam0, frame: 0}
    length_unit: m                      # the reference camera's trajectory unit
    cameras:
      <name>:
        T_cam_ref: 4x4                  # reference camera's frame (reference instant) -> this one's
        T_cam_ref_std: {rotation_deg: [3], translation: [3]}   # right perturbation of R, then t
        unknown_scale: bool
        scale: float                    # reference units per trajectory unit of this camera
        scale_std: float | fixed        # "fixed" where the scale is not estimated
        T_ref_world: 4x4                # the camera's trajectory world (x scale) -> ref frame
        time_offset_s, time_offset_s_std   # with estimate_time_offset: this camera's clock
                                        # minus the reference camera's, seconds
    joints:
      <name>:
        type: ball | hinge | rigid
        between: [p, q]
        position_in: {p: [3], q: [3]}   # ball centre, or the hinge point (nearest p's centre)
        position_std_in: {p: [3], q: [3]}
        axis_in: {p: [3], q: [3]}       # hinge only: unit vectors, largest component in p > 0
        axis_std_deg_in: {p: float, q: float}
        residual_rms: float             # of the joint constraint over the frames used
        frames_used: int
        frames_rejected: int
    bundle_adjustment:                  # when every camera's poses carried board corners
      <name>: {intrinsics_file, rms_px, sigma_px, frames, camera_matrix, distortion,
               intrinsics_std}          # as joint.yaml's quality.bundle_adjustment.<cam>
    warnings: [str]

Every length (``T_cam_ref`` translations, joint positions) is in the reference camera's
units (metres when its trajectory is metric). A camera with unknown scale converts its own
trajectory units to these with ``scale``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from acs_cli.core import se3
from acs_cli.core.rig import JOINT_TYPES
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError
from acs_cli.io.base import YamlArtifact, header_of
from acs_cli.io.joint import BundleSection
from acs_cli.io.validate import (
    as_int,
    as_mapping,
    as_matrix,
    as_number,
    as_scale,
    as_vector,
    optional_number,
)
from acs_cli.io.verdict import VerdictSection

KIND = "rig"

__all__ = ["KIND", "RigArtifact", "RigCameraResult", "RigJointResult"]


@dataclass(frozen=True)
class RigCameraResult:
    """One camera of a calibrated rig (see the module doc for units and frames)."""

    name: str
    T_cam_ref: FloatArray
    rotation_std_deg: FloatArray
    translation_std: FloatArray
    unknown_scale: bool = False
    scale: float = 1.0
    scale_std: float | None = None  # None: fixed, not estimated
    #: maps the camera's trajectory world (its translations times ``scale``) into the
    #: reference camera's frame at the reference instant: T_ref_cam[i] = T_ref_world @
    #: [R_i, scale t_i]; None when not recorded
    T_ref_world: FloatArray | None = None
    #: the camera's clock minus the reference camera's (seconds) and its std, when
    #: estimated (``estimate_time_offset``)
    time_offset_s: float | None = None
    time_offset_s_std: float | None = None


@dataclass(frozen=True)
class RigJointResult:
    """One joint (edge) of a calibrated rig."""

    name: str
    type: str
    between: tuple[str, str]
    position_in: dict[str, FloatArray] = field(default_factory=dict)
    position_std_in: dict[str, FloatArray] = field(default_factory=dict)
    axis_in: dict[str, FloatArray] = field(default_factory=dict)
    axis_std_deg_in: dict[str, float] = field(default_factory=dict)
    residual_rms: float = 0.0
    frames_used: int = 0
    frames_rejected: int = 0


@dataclass(frozen=True)
class RigArtifact(YamlArtifact):
    """A calibrated rig: load, save, validate, summarise (see :class:`~acs_cli.io.base.Artifact`).

    Attributes
    ----------
    reference_camera : str
    reference_frame : int
    length_unit : str
    cameras : dict of RigCameraResult
    joints : dict of RigJointResult
    warnings : list of str
    bundle_adjustment : dict of BundleSection
        Per camera, when the rig was refined on its board corners (refined intrinsics,
        reprojection RMS); empty when solved from poses.
    verdict : VerdictSection or None
        How well the data determined each joint (:mod:`acs_cli.core.quality`).
    header : dict
        The artifact header (tool, inputs, method, units, frames); set when loaded or saved.
    """

    reference_camera: str
    reference_frame: int
    length_unit: str
    cameras: dict[str, RigCameraResult]
    joints: dict[str, RigJointResult]
    warnings: list[str] = field(default_factory=list)
    bundle_adjustment: dict[str, BundleSection] = field(default_factory=dict)
    header: dict[str, Any] = field(default_factory=dict)
    source: str | None = None
    verdict: VerdictSection | None = None

    KIND: ClassVar[str] = KIND
    REQUIRED: ClassVar[tuple[str, ...]] = ("reference.camera", "cameras", "joints")

    # ------------------------------------------------------------------ queries

    def T_a_b(self, a: str, b: str) -> FloatArray:
        """``T_a_b`` at the reference instant: ``T_a_ref @ inv(T_b_ref)``."""
        return np.asarray(
            self.cameras[a].T_cam_ref @ se3.invert_transforms(self.cameras[b].T_cam_ref)
        )

    def summary(self) -> str:
        """A few lines for a person: each camera's position, each joint."""
        u = self.length_unit
        lines = [f"rig: {len(self.cameras)} cameras, {len(self.joints)} joints, "
                 f"reference {self.reference_camera} at frame {self.reference_frame}"]  # fmt: skip
        for c in self.cameras.values():
            centre = -c.T_cam_ref[:3, :3].T @ c.T_cam_ref[:3, 3]
            s = (
                f"  {c.name}: centre in {self.reference_camera} ["
                + " ".join(f"{v:+.4f}" for v in centre)
                + f"] {u} (std {float(np.max(c.translation_std)):.2g})"
            )
            if c.unknown_scale:
                s += f", scale {c.scale:.5g}" + (
                    "" if c.scale_std is None else f" +- {c.scale_std:.2g}"
                )
            lines.append(s)
        for j in self.joints.values():
            s = f"  {j.name} ({j.type}, {j.between[0]}-{j.between[1]})"
            if j.type != "rigid":
                p = j.position_in[j.between[0]]
                s += f": point in {j.between[0]} [" + " ".join(f"{v:+.4f}" for v in p) + f"] {u}"
            if j.type == "hinge":
                a = j.axis_in[j.between[0]]
                s += ", axis [" + " ".join(f"{v:+.3f}" for v in a) + "]"
            s += f", residual RMS {j.residual_rms:.3g}"
            lines.append(s)
        if self.bundle_adjustment:
            b = next(iter(self.bundle_adjustment.values()))
            lines.append(
                f"  bundle adjustment on the corners of {b.frames} frames: RMS "
                + ", ".join(f"{c} {v.rms_px:.3f}" for c, v in self.bundle_adjustment.items())
                + " px"
            )
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    # ------------------------------------------------------------------ io

    def body(self) -> dict[str, Any]:
        """The YAML body (everything but the header)."""
        cams = {}
        for c in self.cameras.values():
            cams[c.name] = {
                "T_cam_ref": c.T_cam_ref,
                "T_cam_ref_std": {
                    "rotation_deg": c.rotation_std_deg,
                    "translation": c.translation_std,
                },
                "unknown_scale": c.unknown_scale,
                "scale": c.scale,
                "scale_std": "fixed" if c.scale_std is None else c.scale_std,
            }
            if c.T_ref_world is not None:
                cams[c.name]["T_ref_world"] = c.T_ref_world
            if c.time_offset_s is not None:
                cams[c.name]["time_offset_s"] = c.time_offset_s
                cams[c.name]["time_offset_s_std"] = c.time_offset_s_std
        joints = {}
        for j in self.joints.values():
            d: dict[str, Any] = {"type": j.type, "between": list(j.between)}
            if j.type != "rigid":
                d["position_in"] = dict(j.position_in)
                d["position_std_in"] = dict(j.position_std_in)
            if j.type == "hinge":
                d["axis_in"] = dict(j.axis_in)
                d["axis_std_deg_in"] = dict(j.axis_std_deg_in)
            d["residual_rms"] = j.residual_rms
            d["frames_used"] = j.frames_used
            d["frames_rejected"] = j.frames_rejected
            joints[j.name] = d
        out = {
            "reference": {"camera": self.reference_camera, "frame": self.reference_frame},
            "length_unit": self.length_unit,
            "cameras": cams,
            "joints": joints,
        }
        if self.bundle_adjustment:
            out["bundle_adjustment"] = {c: b.to_plain() for c, b in self.bundle_adjustment.items()}
        if self.verdict is not None:
            out["verdict"] = self.verdict.to_plain()
        out["warnings"] = list(self.warnings)
        return out

    def validate(self) -> None:
        """Every camera a rigid ``T_cam_ref``; joints between known cameras."""
        for c in self.cameras.values():
            try:
                se3.check_transforms(c.T_cam_ref, name=f"cameras.{c.name}.T_cam_ref")
            except InputError as exc:
                raise InputError(exc.message, path=self.source) from None
        for j in self.joints.values():
            if any(b not in self.cameras for b in j.between):
                raise InputError(
                    f"'joints.{j.name}.between' names an unknown camera", path=self.source
                )

    @classmethod
    def from_doc(cls, doc: dict[str, Any], path: Path) -> RigArtifact:
        """The typed rig from a parsed ``rig.yaml``; errors name the file and the key."""
        p = path
        ref = as_mapping(doc["reference"], "reference", p)
        frame = ref.get("frame", 0)
        if isinstance(frame, bool) or not isinstance(frame, int):
            raise InputError("'reference.frame' must be an integer", path=p)
        cams_doc = as_mapping(doc["cameras"], "cameras", p)
        cameras: dict[str, RigCameraResult] = {}
        for name, c in cams_doc.items():
            k = f"cameras.{name}"
            c = as_mapping(c, k, p)
            T = as_matrix(c.get("T_cam_ref"), (4, 4), f"{k}.T_cam_ref", p)
            std = as_mapping(c.get("T_cam_ref_std", {}), f"{k}.T_cam_ref_std", p)
            scale_std = c.get("scale_std", "fixed")
            cameras[str(name)] = RigCameraResult(
                name=str(name),
                T_cam_ref=T,
                rotation_std_deg=as_vector(
                    std.get("rotation_deg", [0, 0, 0]), f"{k}.T_cam_ref_std.rotation_deg", p
                ),
                translation_std=as_vector(
                    std.get("translation", [0, 0, 0]), f"{k}.T_cam_ref_std.translation", p
                ),
                unknown_scale=bool(c.get("unknown_scale", False)),
                scale=as_scale(c.get("scale", 1.0), f"{k}.scale", p),
                scale_std=None
                if scale_std == "fixed"
                else as_number(scale_std, f"{k}.scale_std", p, non_negative=True),
                T_ref_world=None
                if c.get("T_ref_world") is None
                else as_matrix(c["T_ref_world"], (4, 4), f"{k}.T_ref_world", p),
                time_offset_s=optional_number(c.get("time_offset_s"), f"{k}.time_offset_s", p),
                time_offset_s_std=optional_number(
                    c.get("time_offset_s_std"), f"{k}.time_offset_s_std", p, non_negative=True
                ),
            )
        reference = str(ref["camera"])
        if reference not in cameras:
            raise InputError(f"'reference.camera' {reference!r} is not one of the cameras", path=p)
        joints: dict[str, RigJointResult] = {}
        for name, j in as_mapping(doc["joints"], "joints", p).items():
            k = f"joints.{name}"
            j = as_mapping(j, k, p)
            jtype = j.get("type")
            if jtype not in JOINT_TYPES:
                raise InputError(f"'{k}.type' must be one of {', '.join(JOINT_TYPES)}", path=p)
            between = j.get("between")
            if (
                not isinstance(between, list)
                or len(between) != 2
                or any(str(b) not in cameras for b in between)
            ):
                raise InputError(f"'{k}.between' must name two of the rig's cameras", path=p)
            b = (str(between[0]), str(between[1]))

            def per_cam(key: str, k: str = k, j: Any = j, b: Any = b) -> dict[str, FloatArray]:
                d = as_mapping(j.get(key, {}), f"{k}.{key}", p)
                return {c: as_vector(d[c], f"{k}.{key}.{c}", p) for c in b if c in d}

            pos = per_cam("position_in") if jtype != "rigid" else {}
            if jtype != "rigid" and len(pos) != 2:
                raise InputError(f"'{k}.position_in' needs both {b[0]} and {b[1]}", path=p)
            axis = per_cam("axis_in") if jtype == "hinge" else {}
            if jtype == "hinge" and len(axis) != 2:
                raise InputError(f"'{k}.axis_in' needs both {b[0]} and {b[1]}", path=p)
            ax_std = as_mapping(j.get("axis_std_deg_in", {}), f"{k}.axis_std_deg_in", p)
            joints[str(name)] = RigJointResult(
                name=str(name),
                type=str(jtype),
                between=b,
                position_in=pos,
                position_std_in=per_cam("position_std_in") if jtype != "rigid" else {},
                axis_in=axis,
                axis_std_deg_in={
                    str(c): as_number(v, f"{k}.axis_std_deg_in.{c}", p) for c, v in ax_std.items()
                },
                residual_rms=as_number(j.get("residual_rms", 0.0), f"{k}.residual_rms", p),
                frames_used=as_int(j.get("frames_used", 0), f"{k}.frames_used", p, minimum=0),
                frames_rejected=as_int(
                    j.get("frames_rejected", 0), f"{k}.frames_rejected", p, minimum=0
                ),
            )
        warnings = doc.get("warnings") or []
        if not isinstance(warnings, list):
            raise InputError("'warnings' must be a list", path=p)
        ba_doc = as_mapping(doc.get("bundle_adjustment") or {}, "bundle_adjustment", p)
        bundle = {}
        for c, b in ba_doc.items():
            if str(c) not in cameras:
                raise InputError(f"'bundle_adjustment.{c}' is not one of the cameras", path=p)
            bundle[str(c)] = BundleSection.parse(b, f"bundle_adjustment.{c}", p)
        return cls(
            reference_camera=reference,
            reference_frame=frame,
            length_unit=str(doc.get("length_unit", "m")),
            cameras=cameras,
            joints=joints,
            warnings=[str(w) for w in warnings],
            bundle_adjustment=bundle,
            verdict=None if doc.get("verdict") is None else VerdictSection.parse(doc["verdict"], p),
            header=header_of(doc),
            source=str(p),
        )
