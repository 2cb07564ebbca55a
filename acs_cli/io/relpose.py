"""The relative-pose artifact: ``relpose.yaml`` (``acscal/relpose``).

Keys (after the header): ``scenario`` (``general``), ``relative_pose``
(:class:`RelativePose`), ``joint`` (:class:`~acs_cli.io.joint.JointSection` with
``source``), ``scale`` (:class:`Scale`, with ``--unknown-scale`` only), ``quality``
(:class:`RelposeQuality`) and ``warnings``; ``docs/formats.md`` has the meaning of each.
Reading requires ``relative_pose.T_b_a`` (a rigid 4x4); ``acscal trajectory`` also needs
the joint in both cameras (:meth:`RelposeArtifact.require_joint`).
:func:`load_joint_section` reads the joint of a ``joint.yaml`` or of a ``relpose.yaml``
(``relpose --joint`` takes either).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.base import Section, YamlArtifact, header_of
from acs_cli.io.joint import (
    BundleSection,
    FramesUsed,
    JointArtifact,
    JointSection,
    MotionQuality,
    Pairing,
    PoseNoise,
    UncertaintySection,
    _bundles,
    _fmt,
)
from acs_cli.io.validate import (
    FloatArray,
    as_int,
    as_mapping,
    as_matrix,
    as_number,
    as_scale,
    as_str_list,
    optional_matrix,
    optional_number,
    optional_vector,
)
from acs_cli.io.verdict import VerdictSection

__all__ = [
    "RelativePose",
    "RelposeArtifact",
    "RelposeQuality",
    "Scale",
    "load_joint_artifact",
    "load_joint_section",
]

Source = Path | str | None


@dataclass(frozen=True)
class RelativePose(Section):
    """``relative_pose``: camera B relative to camera A at the reference instant.

    Attributes
    ----------
    T_b_a : ndarray, shape (4, 4)
        Maps camera A's frame into camera B's (the paper's ``H_BA``); translation in B's
        units.
    T_b_a_covariance : ndarray, shape (6, 6) or None
        Of (rotation vector perturbation on the right, rad; ``t_b_a``).
    rpy_deg, rpy_deg_std : ndarray, shape (3,) (std may be None)
        Roll, pitch, yaw of ``R_a_b`` (degrees).
    translation_b_in_a, translation_b_in_a_std : ndarray, shape (3,) (std may be None)
        ``t_a_b``: camera B's origin in A's frame.
    reference : int
        Index of the reference instant among the paired frames.
    reference_timestamp_a, reference_timestamp_b : float or None
        Its timestamps.
    T_wb_wa : ndarray, shape (4, 4) or None
        World A to world B (rotation and translation of the similarity).
    """

    T_b_a: FloatArray
    T_b_a_covariance: FloatArray | None = None
    rpy_deg: FloatArray | None = None
    rpy_deg_std: FloatArray | None = None
    translation_b_in_a: FloatArray | None = None
    translation_b_in_a_std: FloatArray | None = None
    reference: int = 0
    reference_timestamp_a: float | None = None
    reference_timestamp_b: float | None = None
    T_wb_wa: FloatArray | None = None

    @classmethod
    def parse(cls, value: Any, path: Source) -> RelativePose:
        k = "relative_pose"
        d = as_mapping(value, k, path)
        if d.get("T_b_a") is None:
            raise InputError(f"missing key '{k}.T_b_a'", path=path)
        T_b_a = as_matrix(d["T_b_a"], (4, 4), f"{k}.T_b_a", path)
        try:
            se3.check_transforms(T_b_a, name=f"{k}.T_b_a")
        except InputError as exc:
            raise InputError(exc.message, path=path) from None
        return cls(
            T_b_a,
            optional_matrix(
                d.get("T_b_a_covariance"),
                (6, 6),
                f"{k}.T_b_a_covariance",
                path,
                allow_nan=True,
                squared=True,
            ),
            optional_vector(d.get("rpy_deg"), f"{k}.rpy_deg", path),
            optional_vector(d.get("rpy_deg_std"), f"{k}.rpy_deg_std", path, allow_nan=True),
            optional_vector(d.get("translation_b_in_a"), f"{k}.translation_b_in_a", path),
            optional_vector(
                d.get("translation_b_in_a_std"), f"{k}.translation_b_in_a_std", path, allow_nan=True
            ),
            as_int(d.get("reference", 0), f"{k}.reference", path, minimum=0),
            optional_number(d.get("reference_timestamp_a"), f"{k}.reference_timestamp_a", path),
            optional_number(d.get("reference_timestamp_b"), f"{k}.reference_timestamp_b", path),
            optional_matrix(d.get("T_wb_wa"), (4, 4), f"{k}.T_wb_wa", path),
        )


@dataclass(frozen=True)
class Scale(Section):
    """``scale`` (unknown scale only): ``phi_ba = mu_b / mu_a`` and, with a metric joint,
    each trajectory's units per metre, with one-sigma stds."""

    phi_ba: float
    phi_ba_std: float | None = None
    mu_a: float | None = None
    mu_a_std: float | None = None
    mu_b: float | None = None
    mu_b_std: float | None = None

    @classmethod
    def parse(cls, value: Any, path: Source) -> Scale:
        d = as_mapping(value, "scale", path)

        def mu(key: str) -> float | None:
            # trajectory units per metre: exports divide lengths by a positive one
            v = optional_number(d.get(key), f"scale.{key}", path)
            return v if v is None or v <= 0 else as_scale(v, f"scale.{key}", path)

        return cls(
            as_scale(d.get("phi_ba"), "scale.phi_ba", path),
            optional_number(d.get("phi_ba_std"), "scale.phi_ba_std", path, allow_nan=True),
            mu("mu_a"),
            optional_number(d.get("mu_a_std"), "scale.mu_a_std", path, allow_nan=True),
            mu("mu_b"),
            optional_number(d.get("mu_b_std"), "scale.mu_b_std", path, allow_nan=True),
        )


@dataclass(frozen=True)
class RelposeQuality:
    """``relpose.yaml``'s ``quality`` section.

    Attributes
    ----------
    residual_rms : float or None
        RMS of the joint-constraint residual over the frames used (B's units).
    frames : FramesUsed
        Rejected frames by A's timestamps.
    pairing : Pairing or None
    estimated_pose_noise : PoseNoise or None
        ``None`` for the paper's method.
    bundle_adjustment : dict of str to BundleSection
    motion : dict of str to MotionQuality
        A ball joint: how it bent, in each camera's frame (``a``, ``b``), and where it is
        weakest (the schema of ``joint.yaml``'s ``quality.motion``).
    uncertainty : UncertaintySection or None
        How the stds were made (errors correlated over time); None for the paper's method.
    """

    residual_rms: float | None = None
    frames: FramesUsed = field(default_factory=FramesUsed)
    pairing: Pairing | None = None
    estimated_pose_noise: PoseNoise | None = None
    bundle_adjustment: dict[str, BundleSection] = field(default_factory=dict)
    motion: dict[str, MotionQuality] = field(default_factory=dict)
    uncertainty: UncertaintySection | None = None

    @classmethod
    def parse(cls, value: Any, path: Source) -> RelposeQuality:
        d = as_mapping(value or {}, "quality", path)
        noise = d.get("estimated_pose_noise")
        return cls(
            optional_number(d.get("residual_rms"), "quality.residual_rms", path),
            FramesUsed.parse(d.get("frames") or {}, "quality.frames", path),
            None
            if d.get("pairing") is None
            else Pairing.parse(d["pairing"], "quality.pairing", path),
            None if not noise else PoseNoise.parse(noise, "quality.estimated_pose_noise", path),
            _bundles(d.get("bundle_adjustment"), "quality.bundle_adjustment", path),
            MotionQuality.parse_all(d.get("motion"), "quality.motion", path),
            UncertaintySection.parse_optional(d.get("uncertainty"), "quality.uncertainty", path),
        )

    def to_plain(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "residual_rms": self.residual_rms,
            "frames": self.frames.to_plain(),
            "pairing": None if self.pairing is None else self.pairing.to_plain(),
            "estimated_pose_noise": None
            if self.estimated_pose_noise is None
            else self.estimated_pose_noise.to_plain(),
        }
        if self.bundle_adjustment:
            out["bundle_adjustment"] = {k: s.to_plain() for k, s in self.bundle_adjustment.items()}
        if self.motion:
            out["motion"] = {k: m.to_plain() for k, m in self.motion.items()}
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty.to_plain()
        return out


@dataclass(frozen=True)
class TimeOffsetSection(Section):
    """``relpose.yaml``'s ``time_offset``: the constant offset between the cameras' clocks.

    Attributes
    ----------
    time_offset_s : float
        Camera B's clock minus camera A's at one instant, seconds: A's pose stamped ``t``
        pairs with B's at B's time ``t + time_offset_s`` (interpolated on SE(3)).
    time_offset_s_std : float or None
        Its standard deviation, seconds (None when the profile is flat).
    max_offset_s : float
        The range searched, ``[-max_offset_s, max_offset_s]``.
    frames : int
        Frames of A paired at every offset searched.
    """

    time_offset_s: float
    time_offset_s_std: float | None
    max_offset_s: float
    frames: int

    @classmethod
    def parse(cls, value: Any, path: Source) -> TimeOffsetSection:
        d = as_mapping(value, "time_offset", path)
        return cls(
            as_number(d.get("time_offset_s"), "time_offset.time_offset_s", path),
            optional_number(
                d.get("time_offset_s_std"), "time_offset.time_offset_s_std", path,
                non_negative=True,
            ),
            as_number(d.get("max_offset_s"), "time_offset.max_offset_s", path, positive=True),
            as_int(d.get("frames", 0), "time_offset.frames", path, minimum=0),
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class RelposeArtifact(YamlArtifact):
    """The relative pose of two cameras (``acscal/relpose``): Algorithms III, IV and
    self-calibration.

    Attributes
    ----------
    relative_pose : RelativePose
    joint : JointSection or None
        The joint estimated with the relative pose (``source`` says how).
    scale : Scale or None
        Under unknown scale only.
    quality : RelposeQuality
    verdict : VerdictSection or None
        How well the data determined the result (:mod:`acs_cli.core.quality`).
    warnings : list of str
    scenario : str
        ``general``.
    time_offset : TimeOffsetSection or None
        When estimated (``--estimate-time-offset``).
    joint_type : str or None
        The declared joint when not a ball (``--joint-type``): ``hinge`` (``joint`` then has
        its axes) or ``rigid`` (a constant ``T_b_a``: no ``joint`` section, there is no
        joint point). None (no key) for a ball joint.
    header : dict
    source : str or None
    """

    KIND: ClassVar[str] = "relpose"
    REQUIRED: ClassVar[tuple[str, ...]] = ("relative_pose.T_b_a",)

    relative_pose: RelativePose
    joint: JointSection | None = None
    scale: Scale | None = None
    quality: RelposeQuality = field(default_factory=RelposeQuality)
    warnings: list[str] = field(default_factory=list)
    scenario: str = "general"
    time_offset: TimeOffsetSection | None = None
    header: dict[str, Any] = field(default_factory=dict)
    source: str | None = None
    verdict: VerdictSection | None = None
    joint_type: str | None = None

    @property
    def unknown_scale(self) -> bool:
        """Whether the trajectories had unknown scales (a ``scale`` section)."""
        return self.scale is not None

    @property
    def length_unit(self) -> str:
        """The header's ``units.length`` (``m`` when absent)."""
        return str(self.units.get("length", "m"))

    @property
    def phi_ba(self) -> float:
        """``mu_b / mu_a`` (1 under known scale)."""
        return 1.0 if self.scale is None else self.scale.phi_ba

    def require_joint(self) -> JointSection:
        """The joint in both cameras, or an ``InputError`` naming the missing key."""
        if self.joint is None and self.joint_type == "rigid":
            raise InputError(
                "this relpose.yaml is of a rigid pair (joint_type: rigid): it has no joint",
                path=self.source,
            )
        if self.joint is None:
            raise InputError("missing key 'joint.position_in_a'", path=self.source)
        if self.joint.position_in_b is None:
            raise InputError("missing key 'joint.position_in_b'", path=self.source)
        return self.joint

    def validate(self) -> None:
        p = self.source
        as_matrix(self.relative_pose.T_b_a, (4, 4), "relative_pose.T_b_a", p)
        if self.joint is not None:
            self.joint.validate(p)
        if self.scale is not None:
            as_scale(self.scale.phi_ba, "scale.phi_ba", p)

    @classmethod
    def from_doc(cls, doc: dict[str, Any], path: Path) -> RelposeArtifact:
        joint = doc.get("joint")
        return cls(
            relative_pose=RelativePose.parse(doc.get("relative_pose"), path),
            joint=None if joint is None else JointSection.parse(joint, path),
            scale=None if doc.get("scale") is None else Scale.parse(doc["scale"], path),
            quality=RelposeQuality.parse(doc.get("quality"), path),
            verdict=None
            if doc.get("verdict") is None
            else VerdictSection.parse(doc["verdict"], path),
            warnings=as_str_list(doc.get("warnings"), "warnings", path),
            scenario=str(doc.get("scenario", "general")),
            time_offset=None
            if doc.get("time_offset") is None
            else TimeOffsetSection.parse(doc["time_offset"], path),
            header=header_of(doc),
            source=str(path),
            joint_type=None if doc.get("joint_type") is None else str(doc["joint_type"]),
        )

    def body(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "scenario": self.scenario,
        }
        if self.joint_type is not None:
            out["joint_type"] = self.joint_type
        out["relative_pose"] = self.relative_pose.to_plain()
        if self.joint is not None:
            out["joint"] = self.joint.to_plain()
        if self.scale is not None:
            out["scale"] = self.scale.to_plain()
        if self.time_offset is not None:
            out["time_offset"] = self.time_offset.to_plain()
        out["quality"] = self.quality.to_plain()
        if self.verdict is not None:
            out["verdict"] = self.verdict.to_plain()
        out["warnings"] = list(self.warnings)
        return out

    def summary(self) -> str:
        rel = self.relative_pose
        unit_b = "B units" if self.unknown_scale else self.length_unit
        lines = [f"relative pose at reference frame {rel.reference}"]
        if rel.rpy_deg is not None:
            lines.append(f"  R_a_b rpy: {_fmt(rel.rpy_deg, rel.rpy_deg_std, 3)} deg")
        if rel.translation_b_in_a is not None:
            lines.append(
                f"  B's origin in A: {_fmt(rel.translation_b_in_a, rel.translation_b_in_a_std)} "
                f"{unit_b}"
            )
        if self.joint is not None:
            lines += self.joint.summary_lines(unit_b)
        if self.scale is not None:
            s = self.scale
            lines.append(
                f"  phi_ba = mu_b / mu_a: {s.phi_ba:.6g}"
                + ("" if s.phi_ba_std is None else f" +- {s.phi_ba_std:.2g}")
            )
        if self.time_offset is not None:
            o = self.time_offset
            lines.append(
                f"  time offset (B's clock - A's): {1e3 * o.time_offset_s:+.2f}"
                + ("" if o.time_offset_s_std is None else f" +- {1e3 * o.time_offset_s_std:.2g}")
                + " ms"
            )
        if self.quality.residual_rms is not None:
            lines.append(f"  residual RMS: {self.quality.residual_rms:.3g} {unit_b}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)


def load_joint_artifact(path: str | Path) -> JointArtifact | RelposeArtifact:
    """A ``joint.yaml``, or a ``relpose.yaml`` with a joint (``relpose --joint`` takes either);
    the caller reads the joint's unit from it (``length_unit``, ``unknown_scale``).

    Raises
    ------
    InputError
        Neither kind, or a joint that is missing or malformed.
    """
    p = Path(path)
    try:
        return JointArtifact.load(p)
    except InputError as exc:
        if "acscal/relpose" not in exc.message:
            raise
    rel = RelposeArtifact.load(p)
    if rel.joint is None:
        rel.require_joint()  # raises, saying what is missing (a rigid pair has no joint)
    return rel


def load_joint_section(path: str | Path) -> JointSection:
    """The joint of a ``joint.yaml``, or of a ``relpose.yaml`` (its estimated joint), in the
    file's own units (:func:`load_joint_artifact`).

    Raises
    ------
    InputError
        Neither kind, or a joint that is missing or malformed.
    """
    joint = load_joint_artifact(path).joint
    if joint is None:  # load_joint_artifact refuses this; the check keeps the type
        raise InputError("missing key 'joint.position_in_a'", path=path)
    return joint
