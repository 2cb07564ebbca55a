"""The rig artifact: ``rig.yaml``, every camera's pose and every joint of a calibrated rig.

Keys (besides the header of :func:`acs_cli.io.artifacts.make_header`)::

    reference: {camera: cam0, frame: 0}   # and recording: NAME with several recordings
    length_unit: m                      # the reference camera's trajectory unit
    cameras:
      <name>:
        T_cam_ref: 4x4 | null           # reference camera's frame (reference instant) -> this one's
                                        # (null: no pose at the reference instant, a body seen
                                        # only in another recording)
        T_cam_ref_std: {rotation_deg: [3], translation: [3]}   # right perturbation of R, then t
        unknown_scale: bool
        scale: float                    # reference units per trajectory unit of this camera
        scale_std: float | fixed        # "fixed" where the scale is not estimated
        T_ref_world: 4x4                # the camera's trajectory world (x scale) -> ref frame
        time_offset_s, time_offset_s_std   # with estimate_time_offset: this camera's clock
                                        # minus the reference camera's, seconds
        sigma_rotation_deg: float       # its poses' rotation noise per axis, fitted from its
                                        # joints (its ball joints' angle std); absent where
                                        # they do not tell it
        pose_only:                      # a body without corners in the bundle adjustment
          frames: int                   # (a robot's flange, a mocap segment, an INS)
          sigma_rotation_deg: float     # fitted noise of its measured poses, per axis
          sigma_translation: float      # (length units)
          rms_rotation_deg, rms_translation: float   # its pose residuals
          T_world_board: {cam: 4x4}     # each corner camera's board in this body's world
          T_world_board_std: {cam: {rotation_deg: [3], translation: [3]}}
    joints:
      <name>:
        type: ball | hinge | rigid
        between: [p, q]
        position_in: {p: [3], q: [3]}   # ball centre, or the hinge point (nearest p's centre,
                                        # or as joints.<n>.point says: header.frames tells)
        position_std_in: {p: [3], q: [3]}
        axis_in: {p: [3], q: [3]}       # hinge only: unit vectors, signed as joints.<n>.axis says
                                        # (default: largest component in p > 0)
        axis_std_deg_in: {p: float, q: float}
        wobble_rms_deg: float           # a hinge: its bodies' RMS rotation off the axis
        angle_range_deg: [lo, hi]       # a hinge: its angle over the frames used, zero at
                                        # the reference instant, q turning about axis_in
        T_q_p: 4x4                      # rigid only: maps p's frame into q's (hand-eye X)
        T_q_p_std: {rotation_deg: [3], translation: [3]}   # when bundle-adjusted
        residual_rms: float             # of the joint constraint over the frames used
        frames_used: int
        frames_rejected: int
        motion: {p: {...}, q: {...}}    # ball only: how the joint bent, in each body's frame
                                        # (joint.yaml's quality.motion.<a/b> schema)
    bundle_adjustment:                  # when every camera's poses carried board corners
      <name>: {intrinsics_file, rms_px, sigma_px, frames, camera_matrix, distortion,
               intrinsics_std, intrinsics_held}  # as joint.yaml's quality.bundle_adjustment
    uncertainty: {method, blocks, frames, std_factor, grown}  # how the stds were made:
                                        # grown where consecutive frames' errors correlate
    recordings:                         # each recording of the rig and its worlds
      <name>:
        world: shared | separate        # one world for every body, or one per body
        frames: int                     # instants of the rig's timeline in this recording
        worlds:
          <label>:                      # the recording's name (shared) or recording/body
            bodies: [str]
            T_ref_world: 4x4            # the world (x scale) -> the reference camera's frame
            T_ref_world_std: {rotation_deg: [3], translation: [3]}
            scale: float
            scale_std: float | fixed
            tied: bool                  # false: no edge ties it to the reference's world
                                        # (its T_ref_world is then a choice, not an estimate)
        clock: str                      # with estimate_time_offset: the camera whose clock
                                        # the recording's offsets are counted from
        time_offsets: {<camera>: {time_offset_s, time_offset_s_std}}   # its clock minus
                                        # the clock camera's, seconds
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
from acs_cli.core.joints import JOINT_MODELS, JointModel, joint_model
from acs_cli.core.se3 import FloatArray
from acs_cli.errors import InputError
from acs_cli.io.base import YamlArtifact, header_of
from acs_cli.io.joint import BundleSection, MotionQuality, UncertaintySection
from acs_cli.io.validate import (
    Source,
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

__all__ = [
    "KIND",
    "PoseOnlySection",
    "RigArtifact",
    "RigCameraResult",
    "RigJointResult",
    "RigRecordingResult",
]


def _std_plain(std: tuple[FloatArray, FloatArray]) -> dict[str, FloatArray]:
    return {"rotation_deg": std[0], "translation": std[1]}


def _std_parse(value: Any, key: str, path: Path) -> tuple[FloatArray, FloatArray]:
    d = as_mapping(value, key, path)
    return (
        as_vector(d.get("rotation_deg"), f"{key}.rotation_deg", path),
        as_vector(d.get("translation"), f"{key}.translation", path),
    )


@dataclass(frozen=True)
class PoseOnlySection:
    """``cameras.<body>.pose_only``: a body with poses and no corners, in the rig's bundle
    adjustment (its measured poses fitted with their own noise levels).

    Attributes
    ----------
    frames : int
    sigma_rotation_deg, sigma_translation : float
        The fitted noise of its poses, per axis (degrees; length units).
    rms_rotation_deg, rms_translation : float
        RMS of its pose residuals (angle; distance).
    T_world_board : dict of camera to ndarray (4, 4)
        Each corner camera's board frame in this body's world (for a camera on a robot's
        flange: the board in the robot's base, the hand-eye ``Z``).
    T_world_board_std : dict of camera to (rotation_deg (3,), translation (3,))
        Right rotation perturbation, then translation.
    """

    frames: int
    sigma_rotation_deg: float
    sigma_translation: float
    rms_rotation_deg: float
    rms_translation: float
    T_world_board: dict[str, FloatArray] = field(default_factory=dict)
    T_world_board_std: dict[str, tuple[FloatArray, FloatArray]] = field(default_factory=dict)

    def to_plain(self) -> dict[str, Any]:
        return {
            "frames": self.frames,
            "sigma_rotation_deg": self.sigma_rotation_deg,
            "sigma_translation": self.sigma_translation,
            "rms_rotation_deg": self.rms_rotation_deg,
            "rms_translation": self.rms_translation,
            "T_world_board": dict(self.T_world_board),
            "T_world_board_std": {c: _std_plain(v) for c, v in self.T_world_board_std.items()},
        }

    @classmethod
    def parse(cls, value: Any, key: str, path: Path) -> PoseOnlySection:
        d = as_mapping(value, key, path)
        boards = as_mapping(d.get("T_world_board") or {}, f"{key}.T_world_board", path)
        stds = as_mapping(d.get("T_world_board_std") or {}, f"{key}.T_world_board_std", path)

        def num(k: str) -> float:
            return as_number(d.get(k), f"{key}.{k}", path, non_negative=True)

        return cls(
            frames=int(as_number(d.get("frames", 0), f"{key}.frames", path, non_negative=True)),
            sigma_rotation_deg=num("sigma_rotation_deg"),
            sigma_translation=num("sigma_translation"),
            rms_rotation_deg=num("rms_rotation_deg"),
            rms_translation=num("rms_translation"),
            T_world_board={
                str(c): as_matrix(T, (4, 4), f"{key}.T_world_board.{c}", path)
                for c, T in boards.items()
            },
            T_world_board_std={
                str(c): _std_parse(v, f"{key}.T_world_board_std.{c}", path) for c, v in stds.items()
            },
        )


@dataclass(frozen=True)
class RigCameraResult:
    """One camera of a calibrated rig (see the module doc for units and frames)."""

    name: str
    T_cam_ref: FloatArray | None  # None: no pose at the reference instant
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
    #: its poses file held ``T_cam_world`` and was inverted on reading (``invert: true``)
    invert: bool = False
    #: a body without corners in the rig's bundle adjustment (None: a camera, or no bundle)
    pose_only: PoseOnlySection | None = None
    #: its poses' rotation noise per axis (deg) as the rig's solve fitted it from its joints
    #: (the std of the angles of its ball joints); None where they do not tell it
    sigma_rotation_deg: float | None = None


@dataclass(frozen=True)
class RigWorldResult:
    """One world of a recording (see the module doc)."""

    label: str
    bodies: tuple[str, ...]
    T_ref_world: FloatArray
    rotation_std_deg: FloatArray
    translation_std: FloatArray
    scale: float = 1.0
    scale_std: float | None = None
    tied: bool = True


@dataclass(frozen=True)
class RigRecordingResult:
    """One recording of a rig: whether its bodies share a world, its instants, its worlds."""

    name: str
    shared_world: bool
    frames: int
    worlds: dict[str, RigWorldResult] = field(default_factory=dict)
    #: with ``estimate_time_offset``: the camera whose clock the offsets are counted from,
    #: and each camera's clock minus it (seconds, with its std)
    clock: str | None = None
    time_offsets: dict[str, tuple[float, float]] = field(default_factory=dict)


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
    #: a rigid joint's transform (maps p's frame into q's) and, when bundle-adjusted, its
    #: std (rotation_deg (3,) as a right perturbation, translation (3,))
    T_q_p: FloatArray | None = None
    T_q_p_std: tuple[FloatArray, FloatArray] | None = None
    #: a ball joint: how it bent, in each body's frame, and where it is weakest
    motion: dict[str, MotionQuality] = field(default_factory=dict)
    #: a hinge: the RMS rotation of its bodies off the axis over the frames used (deg)
    wobble_rms_deg: float | None = None
    #: a hinge: the lowest and highest angle over the frames used (deg), zero at the
    #: reference instant, ``q`` turning relative to ``p`` about ``axis_in`` (right-hand rule)
    angle_range_deg: tuple[float, float] | None = None

    @property
    def model(self) -> JointModel:
        """Its type's model (:mod:`acs_cli.core.joints`): which fields it has."""
        return joint_model(self.type)


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
    recordings: dict[str, RigRecordingResult] = field(default_factory=dict)
    #: with several recordings: the recording of the reference instant (``reference_frame``
    #: is then a frame of that recording)
    reference_recording: str | None = None
    #: how the stds were made (errors correlated over time; None in older files)
    uncertainty: UncertaintySection | None = None

    KIND: ClassVar[str] = KIND
    REQUIRED: ClassVar[tuple[str, ...]] = ("reference.camera", "cameras", "joints")

    # ------------------------------------------------------------------ queries

    def T_a_b(self, a: str, b: str) -> FloatArray:
        """``T_a_b`` at the reference instant: ``T_a_ref @ inv(T_b_ref)``.

        Raises
        ------
        InputError
            ``a`` or ``b`` has no pose at the reference instant.
        """
        Ta, Tb = self.posed(a), self.posed(b)
        return np.asarray(Ta @ se3.invert_transforms(Tb))

    def posed(self, camera: str) -> FloatArray:
        """``T_cam_ref`` of ``camera``, which must have a pose at the reference instant.

        Raises
        ------
        InputError
            The camera was seen only in another recording than the reference's.
        """
        T = self.cameras[camera].T_cam_ref
        if T is None:
            raise InputError(
                f"cameras.{camera}: no pose at the reference instant (it is seen only in "
                "another recording than the reference's), so its pose relative to the other "
                "cameras is not defined",
                path=self.source,
            )
        return T

    def summary(self) -> str:
        """A few lines for a person: each camera's position, each joint."""
        u = self.length_unit
        lines = [f"rig: {len(self.cameras)} cameras, {len(self.joints)} joints, "
                 f"reference {self.reference_camera} at frame {self.reference_frame}"]  # fmt: skip
        for c in self.cameras.values():
            if c.T_cam_ref is None:
                lines.append(f"  {c.name}: no pose at the reference instant")
                continue
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
            if j.model.has_point:
                p = j.position_in[j.between[0]]
                s += f": point in {j.between[0]} [" + " ".join(f"{v:+.4f}" for v in p) + f"] {u}"
            if j.model.has_axis:
                a = j.axis_in[j.between[0]]
                s += ", axis [" + " ".join(f"{v:+.3f}" for v in a) + "]"
            if j.T_q_p is not None:
                s += (
                    f": T_{j.between[1]}_{j.between[0]} t ["
                    + " ".join(f"{v:+.4f}" for v in j.T_q_p[:3, 3])
                    + f"] {u}"
                )
                if j.T_q_p_std is not None:
                    s += (
                        f" (std {float(np.max(j.T_q_p_std[1])):.2g} {u}, "
                        f"{float(np.max(j.T_q_p_std[0])):.2g} deg)"
                    )
            s += f", residual RMS {j.residual_rms:.3g}"
            lines.append(s)
        for c in self.cameras.values():
            po = c.pose_only
            if po is not None:
                lines.append(
                    f"  {c.name}: poses only, noise {po.sigma_rotation_deg:.3g} deg and "
                    f"{po.sigma_translation:.3g} {u} per axis"
                    + "".join(
                        f"; {b}'s board in its world at ["
                        + " ".join(f"{v:+.4f}" for v in T[:3, 3])
                        + f"] {u}"
                        for b, T in po.T_world_board.items()
                    )
                )
        if self.bundle_adjustment:
            b = next(iter(self.bundle_adjustment.values()))
            lines.append(
                f"  bundle adjustment on the corners of {b.frames} frames"
                + (" (intrinsics held)" if b.intrinsics_held else "")
                + ": RMS "
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
            if c.invert:
                cams[c.name]["invert"] = True
            if c.time_offset_s is not None:
                cams[c.name]["time_offset_s"] = c.time_offset_s
                cams[c.name]["time_offset_s_std"] = c.time_offset_s_std
            if c.pose_only is not None:
                cams[c.name]["pose_only"] = c.pose_only.to_plain()
            if c.sigma_rotation_deg is not None:
                cams[c.name]["sigma_rotation_deg"] = c.sigma_rotation_deg
        joints = {}
        for j in self.joints.values():
            d: dict[str, Any] = {"type": j.type, "between": list(j.between)}
            if j.model.has_point:
                d["position_in"] = dict(j.position_in)
                d["position_std_in"] = dict(j.position_std_in)
            if j.model.has_axis:
                d["axis_in"] = dict(j.axis_in)
                d["axis_std_deg_in"] = dict(j.axis_std_deg_in)
                if j.wobble_rms_deg is not None:
                    d["wobble_rms_deg"] = j.wobble_rms_deg
                if j.angle_range_deg is not None:
                    d["angle_range_deg"] = list(j.angle_range_deg)
            if j.model.constant_transform and j.T_q_p is not None:
                d["T_q_p"] = j.T_q_p
                if j.T_q_p_std is not None:
                    d["T_q_p_std"] = _std_plain(j.T_q_p_std)
            d["residual_rms"] = j.residual_rms
            d["frames_used"] = j.frames_used
            d["frames_rejected"] = j.frames_rejected
            if j.motion:
                d["motion"] = {c: m.to_plain() for c, m in j.motion.items()}
            joints[j.name] = d
        out = {
            "reference": {"camera": self.reference_camera, "frame": self.reference_frame}
            | ({"recording": self.reference_recording} if self.reference_recording else {}),
            "length_unit": self.length_unit,
            "cameras": cams,
            "joints": joints,
        }
        if self.bundle_adjustment:
            out["bundle_adjustment"] = {c: b.to_plain() for c, b in self.bundle_adjustment.items()}
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty.to_plain()
        if self.verdict is not None:
            out["verdict"] = self.verdict.to_plain()
        if self.recordings:
            out["recordings"] = {
                r.name: {
                    "world": "shared" if r.shared_world else "separate",
                    "frames": r.frames,
                    "worlds": {
                        w.label: {
                            "bodies": list(w.bodies),
                            "T_ref_world": w.T_ref_world,
                            "T_ref_world_std": {
                                "rotation_deg": w.rotation_std_deg,
                                "translation": w.translation_std,
                            },
                            "scale": w.scale,
                            "scale_std": "fixed" if w.scale_std is None else w.scale_std,
                            "tied": w.tied,
                        }
                        for w in r.worlds.values()
                    },
                }
                | (
                    {
                        "clock": r.clock,
                        "time_offsets": {
                            c: {"time_offset_s": o, "time_offset_s_std": s}
                            for c, (o, s) in r.time_offsets.items()
                        },
                    }
                    if r.clock is not None
                    else {}
                )
                for r in self.recordings.values()
            }
        out["warnings"] = list(self.warnings)
        return out

    def validate(self) -> None:
        """Every camera a rigid ``T_cam_ref``; joints between known cameras."""
        if self.cameras[self.reference_camera].T_cam_ref is None:
            raise InputError(
                f"'cameras.{self.reference_camera}.T_cam_ref': the reference camera needs a pose",
                path=self.source,
            )
        for c in self.cameras.values():
            if c.T_cam_ref is None:
                continue
            try:
                se3.check_transforms(c.T_cam_ref, name=f"cameras.{c.name}.T_cam_ref")
            except InputError as exc:
                raise InputError(exc.message, path=self.source) from None
            boards = {} if c.pose_only is None else c.pose_only.T_world_board
            for b, T in boards.items():
                key = f"cameras.{c.name}.pose_only.T_world_board.{b}"
                if b not in self.cameras:
                    raise InputError(f"'{key}' is not one of the cameras", path=self.source)
                try:
                    se3.check_transforms(T, name=key)
                except InputError as exc:
                    raise InputError(exc.message, path=self.source) from None
        for j in self.joints.values():
            if any(b not in self.cameras for b in j.between):
                raise InputError(
                    f"'joints.{j.name}.between' names an unknown camera", path=self.source
                )
            if j.T_q_p is not None:
                try:
                    se3.check_transforms(j.T_q_p, name=f"joints.{j.name}.T_q_p")
                except InputError as exc:
                    raise InputError(exc.message, path=self.source) from None

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
            T = (
                None
                if "T_cam_ref" in c and c["T_cam_ref"] is None
                else as_matrix(c.get("T_cam_ref"), (4, 4), f"{k}.T_cam_ref", p)
            )
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
                invert=c.get("invert") is True,
                time_offset_s=optional_number(c.get("time_offset_s"), f"{k}.time_offset_s", p),
                time_offset_s_std=optional_number(
                    c.get("time_offset_s_std"), f"{k}.time_offset_s_std", p, non_negative=True
                ),
                pose_only=None
                if c.get("pose_only") is None
                else PoseOnlySection.parse(c["pose_only"], f"{k}.pose_only", p),
                sigma_rotation_deg=optional_number(
                    c.get("sigma_rotation_deg"), f"{k}.sigma_rotation_deg", p, non_negative=True
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
            if jtype not in JOINT_MODELS:
                raise InputError(f"'{k}.type' must be one of {', '.join(JOINT_MODELS)}", path=p)
            jm = joint_model(str(jtype))
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

            pos = per_cam("position_in") if jm.has_point else {}
            if jm.has_point and len(pos) != 2:
                raise InputError(f"'{k}.position_in' needs both {b[0]} and {b[1]}", path=p)
            axis = per_cam("axis_in") if jm.has_axis else {}
            if jm.has_axis and len(axis) != 2:
                raise InputError(f"'{k}.axis_in' needs both {b[0]} and {b[1]}", path=p)
            ax_std = as_mapping(j.get("axis_std_deg_in", {}), f"{k}.axis_std_deg_in", p)
            joints[str(name)] = RigJointResult(
                name=str(name),
                type=str(jtype),
                between=b,
                position_in=pos,
                position_std_in=per_cam("position_std_in") if jm.has_point else {},
                axis_in=axis,
                axis_std_deg_in={
                    str(c): as_number(v, f"{k}.axis_std_deg_in.{c}", p) for c, v in ax_std.items()
                },
                residual_rms=as_number(j.get("residual_rms", 0.0), f"{k}.residual_rms", p),
                frames_used=as_int(j.get("frames_used", 0), f"{k}.frames_used", p, minimum=0),
                frames_rejected=as_int(
                    j.get("frames_rejected", 0), f"{k}.frames_rejected", p, minimum=0
                ),
                T_q_p=None
                if not jm.constant_transform or j.get("T_q_p") is None
                else as_matrix(j["T_q_p"], (4, 4), f"{k}.T_q_p", p),
                T_q_p_std=None
                if not jm.constant_transform or j.get("T_q_p_std") is None
                else _std_parse(j["T_q_p_std"], f"{k}.T_q_p_std", p),
                motion=MotionQuality.parse_all(j.get("motion"), f"{k}.motion", p),
                wobble_rms_deg=None
                if j.get("wobble_rms_deg") is None
                else as_number(j["wobble_rms_deg"], f"{k}.wobble_rms_deg", p, non_negative=True),
                angle_range_deg=None
                if not jm.has_axis or j.get("angle_range_deg") is None
                else _angle_range(j["angle_range_deg"], f"{k}.angle_range_deg", p),
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
        recordings = _parse_recordings(doc.get("recordings"), p)
        ref_rec = ref.get("recording")
        if ref_rec is not None and str(ref_rec) not in recordings:
            raise InputError(
                f"'reference.recording' {ref_rec!r} is not one of the recordings", path=p
            )
        return cls(
            recordings=recordings,
            reference_recording=None if ref_rec is None else str(ref_rec),
            reference_camera=reference,
            reference_frame=frame,
            length_unit=str(doc.get("length_unit", "m")),
            cameras=cameras,
            joints=joints,
            warnings=[str(w) for w in warnings],
            bundle_adjustment=bundle,
            uncertainty=UncertaintySection.parse_optional(doc.get("uncertainty"), "uncertainty", p),
            verdict=None if doc.get("verdict") is None else VerdictSection.parse(doc["verdict"], p),
            header=header_of(doc),
            source=str(p),
        )


def _parse_recordings(doc: Any, p: Path) -> dict[str, RigRecordingResult]:
    """The ``recordings`` section of a ``rig.yaml`` (absent in files of one recording)."""
    out: dict[str, RigRecordingResult] = {}
    for name, r in as_mapping(doc or {}, "recordings", p).items():
        k = f"recordings.{name}"
        r = as_mapping(r, k, p)
        world = r.get("world", "separate")
        if world not in ("shared", "separate"):
            raise InputError(f"'{k}.world' must be shared or separate", path=p)
        worlds: dict[str, RigWorldResult] = {}
        for label, w in as_mapping(r.get("worlds") or {}, f"{k}.worlds", p).items():
            kw = f"{k}.worlds.{label}"
            w = as_mapping(w, kw, p)
            std = as_mapping(w.get("T_ref_world_std", {}), f"{kw}.T_ref_world_std", p)
            bodies = w.get("bodies") or []
            if not isinstance(bodies, list):
                raise InputError(f"'{kw}.bodies' must be a list", path=p)
            scale_std = w.get("scale_std", "fixed")
            worlds[str(label)] = RigWorldResult(
                label=str(label),
                bodies=tuple(str(b) for b in bodies),
                T_ref_world=as_matrix(w.get("T_ref_world"), (4, 4), f"{kw}.T_ref_world", p),
                rotation_std_deg=as_vector(
                    std.get("rotation_deg", [0, 0, 0]), f"{kw}.T_ref_world_std.rotation_deg", p
                ),
                translation_std=as_vector(
                    std.get("translation", [0, 0, 0]), f"{kw}.T_ref_world_std.translation", p
                ),
                scale=as_number(w.get("scale", 1.0), f"{kw}.scale", p, positive=True),
                scale_std=None
                if scale_std == "fixed"
                else as_number(scale_std, f"{kw}.scale_std", p, non_negative=True),
                tied=bool(w.get("tied", True)),
            )
        frames = as_int(r.get("frames", 0), f"{k}.frames", p, minimum=0)
        offsets = {}
        for c, o in as_mapping(r.get("time_offsets") or {}, f"{k}.time_offsets", p).items():
            ko = f"{k}.time_offsets.{c}"
            o = as_mapping(o, ko, p)
            offsets[str(c)] = (
                as_number(o.get("time_offset_s"), f"{ko}.time_offset_s", p),
                as_number(
                    o.get("time_offset_s_std", 0.0), f"{ko}.time_offset_s_std", p, non_negative=True
                ),
            )
        clock = r.get("clock")
        out[str(name)] = RigRecordingResult(
            str(name), world == "shared", frames, worlds,
            None if clock is None else str(clock), offsets,
        )  # fmt: skip
    return out


def _angle_range(value: Any, key: str, path: Source) -> tuple[float, float]:
    """``[lo, hi]`` degrees with ``lo <= hi`` (a hinge's ``angle_range_deg``)."""
    lo, hi = (float(v) for v in as_vector(value, key, path, 2))
    if lo > hi:
        raise InputError(f"'{key}' must be [lowest, highest], got [{lo:g}, {hi:g}]", path=path)
    return lo, hi
