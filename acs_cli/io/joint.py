"""The joint artifact: ``joint.yaml`` (``acscal/joint``), and the sections it shares with
``relpose.yaml``.

Keys (after the header): ``scenario`` (``fixed_joint`` or ``overlap``), ``joint``
(:class:`JointSection`: ``position_in_a`` and ``_std``, ``position_in_b`` and ``_std``,
``covariance_a``, ``covariance_b``, ``units``), ``quality`` (:class:`JointQuality`) and
``warnings``; ``docs/formats.md`` has the meaning of each.
:func:`acs_cli.io.relpose.load_joint_section` reads the joint of a ``joint.yaml`` or of a
``relpose.yaml`` (``relpose --joint`` takes either).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from acs_cli.core.correlated import CorrelatedErrors
from acs_cli.core.intrinsics import DISTORTION_NAMES
from acs_cli.errors import InputError
from acs_cli.io.base import Section, YamlArtifact, header_of
from acs_cli.io.validate import (
    FloatArray,
    as_bool,
    as_int,
    as_mapping,
    as_matrix,
    as_number,
    as_str_list,
    as_vector,
    listed_mask,
    optional_covariance3,
    optional_number,
    optional_vector,
)
from acs_cli.io.verdict import VerdictSection

__all__ = [
    "BundleSection",
    "FramesUsed",
    "JointArtifact",
    "JointQuality",
    "JointSection",
    "MotionQuality",
    "Pairing",
    "PoseNoise",
]

if TYPE_CHECKING:
    from acs_cli.core.joint import MotionSummary

Source = Path | str | None


def _fmt(v: FloatArray, std: FloatArray | None, digits: int = 4) -> str:
    text = "[" + " ".join(f"{x:+.{digits}f}" for x in v) + "]"
    if std is not None:
        text += " +- [" + " ".join(f"{x:.2g}" for x in std) + "]"
    return text


# ----------------------------------------------------------------------------- sections


@dataclass(frozen=True)
class FramesUsed:
    """``quality.frames``: how many frames an estimator used and which it rejected.

    Attributes
    ----------
    total, used : int or None
    rejected : list of float
        Timestamps (s, or frame numbers) of the frames rejected as outliers.
    """

    total: int | None = None
    used: int | None = None
    rejected: list[float] = field(default_factory=list)

    @classmethod
    def from_inliers(
        cls, inliers: NDArray[np.bool_], labels: NDArray[Any] | None = None
    ) -> FramesUsed:
        """From a mask ``(n,)`` of the frames used; ``rejected`` by ``labels`` (timestamps)
        or by index."""
        rejected = np.flatnonzero(~inliers)
        listed = rejected if labels is None else np.asarray(labels)[rejected]
        return cls(int(inliers.size), int(inliers.sum()), [x.item() for x in listed])

    @classmethod
    def parse(cls, value: Any, key: str, path: Source) -> FramesUsed:
        d = as_mapping(value, key, path)
        rej = d.get("rejected") or []
        if not isinstance(rej, list):
            raise InputError(f"'{key}.rejected' must be a list", path=path)
        return cls(
            None if d.get("total") is None else as_int(d["total"], f"{key}.total", path),
            None if d.get("used") is None else as_int(d["used"], f"{key}.used", path),
            [as_number(v, f"{key}.rejected[{i}]", path) for i, v in enumerate(rej)],
        )

    def to_plain(self) -> dict[str, Any]:
        return {"total": self.total, "used": self.used, "rejected": list(self.rejected)}

    def mask(self, labels: NDArray[Any]) -> NDArray[np.bool_]:
        """Which of ``labels`` (timestamps, ``(n,)``) were rejected."""
        return listed_mask(labels, self.rejected)


PAIR_BY = ("auto", "timestamp", "index")


@dataclass(frozen=True)
class Pairing(Section):
    """``quality.pairing``: how A's and B's samples were paired.

    Attributes
    ----------
    by : str
        ``timestamp`` or ``index``, as done.
    requested : str
        ``--pair-by`` as given (``auto``, ``timestamp`` or ``index``).
    pairs, unpaired_a, unpaired_b : int
    max_dt_s : float or None
        Largest timestamp difference of a pair, seconds (None when paired by index).
    """

    by: str = "timestamp"
    requested: str = "auto"
    pairs: int = 0
    unpaired_a: int = 0
    unpaired_b: int = 0
    max_dt_s: float | None = None

    @classmethod
    def parse(cls, value: Any, key: str, path: Source) -> Pairing:
        d = as_mapping(value, key, path)
        return cls(
            str(d.get("by", "timestamp")),
            str(d.get("requested", "auto")),
            as_int(d.get("pairs", 0), f"{key}.pairs", path, minimum=0),
            as_int(d.get("unpaired_a", 0), f"{key}.unpaired_a", path, minimum=0),
            as_int(d.get("unpaired_b", 0), f"{key}.unpaired_b", path, minimum=0),
            optional_number(d.get("max_dt_s"), f"{key}.max_dt_s", path, non_negative=True),
        )

    @property
    def pair_by(self) -> str:
        """The ``--pair-by`` to repeat this pairing (``auto`` for an unknown value)."""
        return self.requested if self.requested in PAIR_BY else "auto"


@dataclass(frozen=True)
class PoseNoise(Section):
    """Estimated pose noise: translation (length unit) and rotation (deg), per axis."""

    sigma_trans: float
    sigma_rot_deg: float

    @classmethod
    def parse(cls, value: Any, key: str, path: Source) -> PoseNoise:
        d = as_mapping(value, key, path)
        return cls(
            as_number(d.get("sigma_trans"), f"{key}.sigma_trans", path),
            as_number(d.get("sigma_rot_deg"), f"{key}.sigma_rot_deg", path),
        )


@dataclass(frozen=True)
class MotionQuality(Section):
    """How a ball joint's body turned and where the joint is weakest, in that body's frame
    (:class:`acs_cli.core.joint.MotionSummary`): ``joint.yaml``'s and ``relpose.yaml``'s
    ``quality.motion.<a/b>`` (fixed joint: the camera's rotations; overlap, relative pose:
    the articulation between the two cameras) and ``rig.yaml``'s ``joints.<j>.motion.<camera>``.

    Attributes
    ----------
    dominant_axis : ndarray, shape (3,)
        The axis the body turned about most, in its frame (a near-hinge's hinge axis).
    other_axes : ndarray, shape (2, 3)
        The two other principal rotation axes (rows), in the body's frame.
    rotation_spread_deg : ndarray, shape (3,)
        RMS rotation about the dominant axis and the two others, degrees.
    rotation_ratio : float
        Weakest over strongest singular value of the stacked, centred rotations.
    near_hinge : bool
        ``rotation_ratio`` below the hinge rule's ``HINGE_RATIO`` (and not refused).
    weak_direction : ndarray, shape (3,)
        Unit direction, body frame, along which the joint is least determined.
    weak_std : float
        The joint's standard deviation along it (length unit).
    """

    dominant_axis: FloatArray
    other_axes: FloatArray
    rotation_spread_deg: FloatArray
    rotation_ratio: float
    near_hinge: bool
    weak_direction: FloatArray
    weak_std: float

    @classmethod
    def from_motion(cls, motion: MotionSummary, covariance: FloatArray) -> MotionQuality:
        """From a camera's motion summary and its joint's covariance ``(3, 3)``."""
        from acs_cli.core.joint import weakest_direction

        weak, std = weakest_direction(covariance)
        return cls(
            np.asarray(motion.dominant_axis, dtype=float),
            np.asarray(motion.axes[1:], dtype=float),
            np.asarray(motion.spread_deg, dtype=float),
            float(motion.ratio),
            bool(motion.near_hinge),
            weak,
            std,
        )

    @classmethod
    def parse(cls, value: Any, key: str, path: Source) -> MotionQuality:
        d = as_mapping(value, key, path)
        return cls(
            as_vector(d.get("dominant_axis"), f"{key}.dominant_axis", path),
            as_matrix(d.get("other_axes"), (2, 3), f"{key}.other_axes", path),
            as_vector(d.get("rotation_spread_deg"), f"{key}.rotation_spread_deg", path),
            as_number(d.get("rotation_ratio"), f"{key}.rotation_ratio", path, non_negative=True),
            as_bool(d.get("near_hinge"), f"{key}.near_hinge", path),
            as_vector(d.get("weak_direction"), f"{key}.weak_direction", path),
            as_number(d.get("weak_std"), f"{key}.weak_std", path, non_negative=True),
        )

    @classmethod
    def of(
        cls, motion: dict[str, MotionSummary], covariance: dict[str, FloatArray | None]
    ) -> dict[str, MotionQuality]:
        """Per body, from the motion summaries and the joint's covariances ``(3, 3)`` (bodies
        without a covariance are left out)."""
        return {
            k: cls.from_motion(m, cov)
            for k, m in motion.items()
            if (cov := covariance.get(k)) is not None
        }

    @classmethod
    def parse_all(cls, value: Any, key: str, path: Source) -> dict[str, MotionQuality]:
        """A mapping of body to :class:`MotionQuality` (absent: empty)."""
        return {
            k: cls.parse(v, f"{key}.{k}", path)
            for k, v in as_mapping(value or {}, key, path).items()
        }


@dataclass(frozen=True)
class UncertaintySection(Section):
    """How an estimate's stds were made (:class:`acs_cli.core.correlated.CorrelatedErrors`):
    ``joint.yaml``'s ``quality.uncertainty.<a/b/ab>``, ``relpose.yaml``'s
    ``quality.uncertainty`` and ``rig.yaml``'s ``uncertainty``.

    Attributes
    ----------
    method : str
        The covariance: the model's (independent frames, noise levels fitted), grown by the
        block sandwich where consecutive frames' errors are correlated.
    blocks : int
        Blocks of consecutive frames the test cut the recording into (0: too few frames, not
        tested).
    frames : int
        Frames the test used.
    std_factor : float
        The largest factor a std grew by (1.0: the model's covariance stands).
    grown : list of str
        The quantities whose stds grew (joints, worlds, intrinsics), by name.
    """

    method: str
    blocks: int
    frames: int
    std_factor: float
    grown: list[str] = field(default_factory=list)

    @classmethod
    def of(cls, found: CorrelatedErrors) -> UncertaintySection:
        if not found.tested:
            how = "independent frames, noise levels fitted (too few frames for the block test)"
        elif found.detected:
            how = (
                "independent frames, noise levels fitted, grown by the block sandwich: "
                "the residuals are correlated over consecutive frames"
            )
        else:
            how = (
                "independent frames, noise levels fitted (the block test over consecutive "
                "frames found no correlated errors)"
            )
        return cls(how, found.blocks, found.frames, round(found.std_factor, 4), list(found.grown))

    @classmethod
    def parse(cls, value: Any, key: str, path: Source) -> UncertaintySection:
        d = as_mapping(value, key, path)
        return cls(
            str(d.get("method", "")),
            as_int(d.get("blocks", 0), f"{key}.blocks", path, minimum=0),
            as_int(d.get("frames", 0), f"{key}.frames", path, minimum=0),
            as_number(d.get("std_factor", 1.0), f"{key}.std_factor", path),
            as_str_list(d.get("grown") or [], f"{key}.grown", path),
        )

    @classmethod
    def parse_optional(cls, value: Any, key: str, path: Source) -> UncertaintySection | None:
        return None if value is None else cls.parse(value, key, path)


@dataclass(frozen=True)
class BundleSection(Section):
    """``quality.bundle_adjustment.<cam>``: one camera's bundle adjustment on its corners.

    Attributes
    ----------
    intrinsics_file : str
        The initial intrinsics.
    rms_px, sigma_px : float
        Reprojection RMS and estimated corner noise, pixels.
    frames : int
        Frames adjusted.
    camera_matrix : ndarray, shape (3, 3)
        Refined ``K``, pixels.
    distortion : ndarray, shape (m,)
        Refined coefficients of ``model`` (``k1 k2 p1 p2 k3`` for pinhole).
    intrinsics_std : dict of str to float
        One sigma of ``fx fy cx cy`` and the coefficients, by name.
    model : str
        The camera model (``pinhole`` when the file does not say).
    intrinsics_held : bool
        The intrinsics were held, not refined: ``camera_matrix`` and ``distortion`` are the
        file's, with its std (none when it gives none).
    """

    intrinsics_file: str
    rms_px: float
    sigma_px: float
    frames: int
    camera_matrix: FloatArray
    distortion: FloatArray
    intrinsics_std: dict[str, float] = field(default_factory=dict)
    model: str = "pinhole"
    intrinsics_held: bool = False

    @classmethod
    def parse(cls, value: Any, key: str, path: Source) -> BundleSection:
        d = as_mapping(value, key, path)
        model = str(d.get("model", "pinhole"))
        if model not in DISTORTION_NAMES:
            raise InputError(f"'{key}.model' is not a camera model: {model!r}", path=path)
        dist = d.get("distortion") or []
        if not isinstance(dist, list):
            raise InputError(f"'{key}.distortion' must be a list of numbers", path=path)
        dist_arr = as_matrix(dist, (len(dist),), f"{key}.distortion", path)
        std = as_mapping(d.get("intrinsics_std") or {}, f"{key}.intrinsics_std", path)
        return cls(
            str(d.get("intrinsics_file", "")),
            as_number(d.get("rms_px"), f"{key}.rms_px", path),
            as_number(d.get("sigma_px"), f"{key}.sigma_px", path),
            as_int(d.get("frames", 0), f"{key}.frames", path, minimum=0),
            as_matrix(d.get("camera_matrix"), (3, 3), f"{key}.camera_matrix", path),
            dist_arr,
            {
                k: as_number(v, f"{key}.intrinsics_std.{k}", path, allow_nan=True)
                for k, v in std.items()
            },
            model,
            as_bool(d.get("intrinsics_held", False), f"{key}.intrinsics_held", path),
        )

    def values(self) -> dict[str, float]:
        """``fx fy cx cy`` and the distortion coefficients by name."""
        K = self.camera_matrix
        vals = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
        for name, v in zip(DISTORTION_NAMES[self.model], self.distortion, strict=False):
            vals[name] = v
        return {k: float(v) for k, v in vals.items()}


def _bundles(value: Any, key: str, path: Source) -> dict[str, BundleSection]:
    d = as_mapping(value or {}, key, path)
    return {cam: BundleSection.parse(sec, f"{key}.{cam}", path) for cam, sec in d.items()}


@dataclass(frozen=True)
class JointSection:
    """The ``joint`` section of ``joint.yaml`` and ``relpose.yaml``.

    Attributes
    ----------
    position_in_a : ndarray, shape (3,)
        The joint in camera A's frame (the paper's ``O_A``), length unit.
    position_in_b : ndarray, shape (3,) or None
        The joint in camera B's frame, when known.
    position_in_a_std, position_in_b_std : ndarray, shape (3,) or None
        One sigma of each coordinate.
    covariance_a, covariance_b : ndarray, shape (3, 3) or None
        Symmetric PSD covariances of the positions.
    units : str or None
        The length unit (``joint.yaml`` only).
    source : str or None
        Where the joint came from (``relpose.yaml`` only).
    type : str or None
        The declared joint type when not a ball (``--joint-type hinge``); None (no key) for
        a ball joint.
    axis_in_a, axis_in_b : ndarray, shape (3,) or None
        A hinge's unit axis in each camera's frame (then ``position_in_a`` is the axis point
        nearest camera A's centre and ``position_in_b`` the same point in B).
    axis_in_a_std_deg, axis_in_b_std_deg : float or None
        One sigma of each axis direction (degrees, both directions across it together).
    """

    position_in_a: FloatArray
    position_in_b: FloatArray | None = None
    position_in_a_std: FloatArray | None = None
    position_in_b_std: FloatArray | None = None
    covariance_a: FloatArray | None = None
    covariance_b: FloatArray | None = None
    units: str | None = None
    source: str | None = None
    type: str | None = None
    axis_in_a: FloatArray | None = None
    axis_in_b: FloatArray | None = None
    axis_in_a_std_deg: float | None = None
    axis_in_b_std_deg: float | None = None

    def with_axes(
        self,
        joint_type: str,
        axis_in: dict[str, FloatArray],
        axis_std_deg_in: dict[str, float],
    ) -> JointSection:
        """The section with a declared non-ball type and its axes (a ball's is unchanged)."""
        if joint_type == "ball":
            return self

        def vec(c: str) -> FloatArray | None:
            return np.asarray(axis_in[c], dtype=float) if c in axis_in else None

        def std(c: str) -> float | None:
            return float(axis_std_deg_in[c]) if c in axis_std_deg_in else None

        return replace(
            self,
            type=joint_type,
            axis_in_a=vec("a"),
            axis_in_b=vec("b"),
            axis_in_a_std_deg=std("a"),
            axis_in_b_std_deg=std("b"),
        )

    @classmethod
    def from_estimate(
        cls,
        position_in_a: FloatArray,
        covariance_a: FloatArray | None,
        position_in_b: FloatArray | None = None,
        covariance_b: FloatArray | None = None,
        *,
        units: str | None = None,
        source: str | None = None,
    ) -> JointSection:
        """From positions and covariances; the stds are the covariances' diagonals' roots."""

        def std(cov: FloatArray | None) -> FloatArray | None:
            return None if cov is None else np.sqrt(np.maximum(np.diag(cov), 0.0))

        return cls(
            np.asarray(position_in_a, dtype=float),
            None if position_in_b is None else np.asarray(position_in_b, dtype=float),
            std(covariance_a),
            None if position_in_b is None else std(covariance_b),
            None if covariance_a is None else np.asarray(covariance_a, dtype=float),
            None if covariance_b is None else np.asarray(covariance_b, dtype=float),
            units,
            source,
        )

    @classmethod
    def parse(cls, value: Any, path: Source, key: str = "joint") -> JointSection:
        """Parse and validate a ``joint`` mapping (``position_in_a`` required)."""
        d = as_mapping(value, key, path)
        if d.get("position_in_a") is None:
            raise InputError(f"missing key '{key}.position_in_a'", path=path)
        return cls(
            as_vector(d["position_in_a"], f"{key}.position_in_a", path),
            optional_vector(d.get("position_in_b"), f"{key}.position_in_b", path),
            optional_vector(d.get("position_in_a_std"), f"{key}.position_in_a_std", path),
            optional_vector(d.get("position_in_b_std"), f"{key}.position_in_b_std", path),
            optional_covariance3(d.get("covariance_a"), f"{key}.covariance_a", path),
            optional_covariance3(d.get("covariance_b"), f"{key}.covariance_b", path),
            None if d.get("units") is None else str(d["units"]),
            None if d.get("source") is None else str(d["source"]),
            None if d.get("type") is None else str(d["type"]),
            optional_vector(d.get("axis_in_a"), f"{key}.axis_in_a", path),
            optional_vector(d.get("axis_in_b"), f"{key}.axis_in_b", path),
            _optional_std_deg(d.get("axis_in_a_std_deg"), f"{key}.axis_in_a_std_deg", path),
            _optional_std_deg(d.get("axis_in_b_std_deg"), f"{key}.axis_in_b_std_deg", path),
        )

    def to_plain(self) -> dict[str, Any]:
        """The mapping in file order: positions with stds, covariances, units or source."""
        out: dict[str, Any] = {
            "position_in_a": self.position_in_a,
            "position_in_a_std": self.position_in_a_std,
        }
        if self.position_in_b is not None:
            out["position_in_b"] = self.position_in_b
            out["position_in_b_std"] = self.position_in_b_std
        if self.covariance_a is not None:
            out["covariance_a"] = self.covariance_a
        if self.covariance_b is not None:
            out["covariance_b"] = self.covariance_b
        if self.type is not None:
            out["type"] = self.type
        for key in ("axis_in_a", "axis_in_a_std_deg", "axis_in_b", "axis_in_b_std_deg"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.units is not None:
            out["units"] = self.units
        if self.source is not None:
            out["source"] = self.source
        return out

    def position(self, cam: str) -> FloatArray | None:
        """``position_in_a`` or ``position_in_b`` (``cam`` is ``"a"`` or ``"b"``)."""
        return self.position_in_a if cam == "a" else self.position_in_b

    def std(self, cam: str) -> FloatArray | None:
        """One sigma of :meth:`position`."""
        return self.position_in_a_std if cam == "a" else self.position_in_b_std

    def covariance(self, cam: str) -> FloatArray | None:
        """The covariance of :meth:`position`, else the squares of its stds, else None."""
        cov = self.covariance_a if cam == "a" else self.covariance_b
        if cov is None:
            std = self.std(cam)
            cov = None if std is None else np.diag(np.square(std))
        return cov

    def validate(self, path: Source) -> None:
        """Re-check shapes and finiteness, the covariances (symmetric, positive
        semi-definite) and that each std agrees with its covariance's diagonal."""
        as_vector(self.position_in_a, "joint.position_in_a", path)
        for cam in ("a", "b"):
            optional_vector(self.position(cam), f"joint.position_in_{cam}", path)
            std = optional_vector(self.std(cam), f"joint.position_in_{cam}_std", path)
            cov = optional_covariance3(
                self.covariance_a if cam == "a" else self.covariance_b,
                f"joint.covariance_{cam}",
                path,
            )
            if std is not None and np.any(std < 0):
                raise InputError(f"'joint.position_in_{cam}_std' must not be negative", path=path)
            if std is not None and cov is not None:
                _check_std_matches(std, cov, cam, path)

    def scaled(self, factor: float, units: str) -> JointSection:
        """The section with its lengths multiplied by ``factor`` (a change of unit to
        ``units``): positions and stds by ``factor``, covariances by its square."""

        def mul(x: FloatArray | None, f: float) -> FloatArray | None:
            return None if x is None else np.asarray(x, dtype=float) * f

        return JointSection(
            np.asarray(self.position_in_a, dtype=float) * factor,
            mul(self.position_in_b, factor),
            mul(self.position_in_a_std, factor),
            mul(self.position_in_b_std, factor),
            mul(self.covariance_a, factor**2),
            mul(self.covariance_b, factor**2),
            units,
            self.source,
            self.type,
            self.axis_in_a,
            self.axis_in_b,
            self.axis_in_a_std_deg,
            self.axis_in_b_std_deg,
        )

    def summary_lines(self, unit: str) -> list[str]:
        lines = [f"  joint in A: {_fmt(self.position_in_a, self.position_in_a_std)} {unit}"]
        if self.position_in_b is not None:
            lines.append(f"  joint in B: {_fmt(self.position_in_b, self.position_in_b_std)} {unit}")
        for cam, axis, std in (
            ("A", self.axis_in_a, self.axis_in_a_std_deg),
            ("B", self.axis_in_b, self.axis_in_b_std_deg),
        ):
            if axis is not None:
                sd = "" if std is None else f" +- {std:.3g} deg"
                lines.append(f"  {self.type or 'hinge'} axis in {cam}: {_fmt(axis, None)}{sd}")
        return lines


def _optional_std_deg(value: Any, key: str, path: Source) -> float | None:
    """A non-negative finite number of degrees, or None."""
    if value is None:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"'{key}' must be a number of degrees", path=path) from None
    if not np.isfinite(x) or x < 0:
        raise InputError(f"'{key}' must be a finite non-negative number of degrees", path=path)
    return x


#: Largest difference between a std and the root of its covariance's diagonal, relative to
#: the largest of them (stds rounded by hand to two digits pass).
STD_TOL = 0.05


def _check_std_matches(std: FloatArray, cov: FloatArray, cam: str, path: Source) -> None:
    """An ``InputError`` when ``position_in_<cam>_std`` is not ``sqrt(diag(covariance_<cam>))``
    (within :data:`STD_TOL` of the largest): the file says two things about one sigma."""
    root = np.sqrt(np.maximum(np.diag(cov), 0.0))
    if np.abs(std - root).max() > STD_TOL * max(float(np.abs(std).max()), float(root.max())):
        raise InputError(
            f"'joint.position_in_{cam}_std' {_fmt(std, None, 6)} disagrees with the square "
            f"roots of the diagonal of 'joint.covariance_{cam}' {_fmt(root, None, 6)}: correct "
            "one, or remove the std (it is then taken from the covariance)",
            path=path,
        )


@dataclass(frozen=True)
class JointQuality:
    """``joint.yaml``'s ``quality`` section.

    Attributes
    ----------
    frames : dict of str to FramesUsed
        ``a`` and ``b`` (fixed joint) or ``ab`` (overlap).
    residual_rms : dict of str to float, or float
        RMS of the joint-constraint residual per key (length unit).
    pairing : Pairing or None
        Overlap only.
    joint_in_world : dict of str to ndarray (3,)
        Fixed joint only: the joint in each trajectory's world.
    estimated_pose_noise : dict of str to PoseNoise
        Refined method only.
    bundle_adjustment : dict of str to BundleSection
        Per camera, when the corners were adjusted.
    motion : dict of str to MotionQuality
        Ball joints: how each camera turned (fixed joint) or how the joint bent (overlap),
        in each camera's frame, and where the joint is weakest.
    uncertainty : dict of str to UncertaintySection
        Per key, how the stds were made (errors correlated over time).
    """

    frames: dict[str, FramesUsed] = field(default_factory=dict)
    residual_rms: dict[str, float] | float = field(default_factory=dict)
    pairing: Pairing | None = None
    joint_in_world: dict[str, FloatArray] = field(default_factory=dict)
    estimated_pose_noise: dict[str, PoseNoise] = field(default_factory=dict)
    bundle_adjustment: dict[str, BundleSection] = field(default_factory=dict)
    motion: dict[str, MotionQuality] = field(default_factory=dict)
    uncertainty: dict[str, UncertaintySection] = field(default_factory=dict)

    @classmethod
    def parse(cls, value: Any, path: Source) -> JointQuality:
        d = as_mapping(value or {}, "quality", path)
        frames = as_mapping(d.get("frames") or {}, "quality.frames", path)
        world = as_mapping(d.get("joint_in_world") or {}, "quality.joint_in_world", path)
        noise = as_mapping(
            d.get("estimated_pose_noise") or {}, "quality.estimated_pose_noise", path
        )
        rms_raw = d.get("residual_rms")
        rms: dict[str, float] | float
        if isinstance(rms_raw, dict):
            rms = {
                str(k): as_number(v, f"quality.residual_rms.{k}", path) for k, v in rms_raw.items()
            }
        elif rms_raw is None:
            rms = {}
        else:
            rms = as_number(rms_raw, "quality.residual_rms", path)
        return cls(
            {k: FramesUsed.parse(v, f"quality.frames.{k}", path) for k, v in frames.items()},
            rms,
            None
            if d.get("pairing") is None
            else Pairing.parse(d["pairing"], "quality.pairing", path),
            {k: as_vector(v, f"quality.joint_in_world.{k}", path) for k, v in world.items()},
            {
                k: PoseNoise.parse(v, f"quality.estimated_pose_noise.{k}", path)
                for k, v in noise.items()
            },
            _bundles(d.get("bundle_adjustment"), "quality.bundle_adjustment", path),
            MotionQuality.parse_all(d.get("motion"), "quality.motion", path),
            {
                k: UncertaintySection.parse(v, f"quality.uncertainty.{k}", path)
                for k, v in as_mapping(
                    d.get("uncertainty") or {}, "quality.uncertainty", path
                ).items()
            },
        )

    def to_plain(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.bundle_adjustment:
            out["bundle_adjustment"] = {k: s.to_plain() for k, s in self.bundle_adjustment.items()}
        if self.pairing is not None:
            out["pairing"] = self.pairing.to_plain()
        out["frames"] = {k: f.to_plain() for k, f in self.frames.items()}
        if self.joint_in_world:
            out["joint_in_world"] = dict(self.joint_in_world)
        out["residual_rms"] = (
            dict(self.residual_rms) if isinstance(self.residual_rms, dict) else self.residual_rms
        )
        if self.estimated_pose_noise:
            out["estimated_pose_noise"] = {
                k: n.to_plain() for k, n in self.estimated_pose_noise.items()
            }
        if self.motion:
            out["motion"] = {k: m.to_plain() for k, m in self.motion.items()}
        if self.uncertainty:
            out["uncertainty"] = {k: u.to_plain() for k, u in self.uncertainty.items()}
        return out


# ----------------------------------------------------------------------------- the artifact

SCENARIOS = ("fixed_joint", "overlap")


@dataclass(frozen=True, eq=False)
class JointArtifact(YamlArtifact):
    """The joint of an ACS (``acscal/joint``): Algorithm I (overlap) or II (fixed joint).

    Attributes
    ----------
    scenario : {"fixed_joint", "overlap"}
    joint : JointSection
        Positions in camera A's and B's frames (``units`` their length unit).
    quality : JointQuality
    verdict : VerdictSection or None
        How well the data determined the result (:mod:`acs_cli.core.quality`).
    warnings : list of str
    header : dict
    source : str or None
    """

    KIND: ClassVar[str] = "joint"
    REQUIRED: ClassVar[tuple[str, ...]] = ("joint.position_in_a",)

    scenario: str
    joint: JointSection
    quality: JointQuality = field(default_factory=JointQuality)
    warnings: list[str] = field(default_factory=list)
    header: dict[str, Any] = field(default_factory=dict)
    source: str | None = None
    verdict: VerdictSection | None = None

    @property
    def length_unit(self) -> str:
        """The positions' length unit (``joint.units``, else the header's, else ``m``)."""
        if self.joint.units is not None:
            return self.joint.units
        return str(self.units.get("length", "m"))

    def validate(self) -> None:
        if self.scenario not in SCENARIOS:
            raise InputError(
                f"'scenario' must be one of {', '.join(SCENARIOS)}, got {self.scenario!r}",
                path=self.source,
            )
        self.joint.validate(self.source)
        header_unit = self.units.get("length")
        if self.joint.units is not None and header_unit is not None:
            if str(header_unit) != self.joint.units:
                raise InputError(
                    f"'joint.units' ({self.joint.units}) and the header's 'units.length' "
                    f"({header_unit}) differ: the positions' unit is ambiguous",
                    path=self.source,
                )

    @classmethod
    def from_doc(cls, doc: dict[str, Any], path: Path) -> JointArtifact:
        return cls(
            scenario=str(doc.get("scenario", "fixed_joint")),
            joint=JointSection.parse(doc.get("joint"), path),
            quality=JointQuality.parse(doc.get("quality"), path),
            verdict=None
            if doc.get("verdict") is None
            else VerdictSection.parse(doc["verdict"], path),
            warnings=as_str_list(doc.get("warnings"), "warnings", path),
            header=header_of(doc),
            source=str(path),
        )

    def body(self) -> dict[str, Any]:
        return {
            "scenario": self.scenario,
            "joint": self.joint.to_plain(),
            "quality": self.quality.to_plain(),
            **({} if self.verdict is None else {"verdict": self.verdict.to_plain()}),
            "warnings": list(self.warnings),
        }

    def summary(self) -> str:
        u = self.length_unit
        lines = [f"joint ({self.scenario}): {self.header.get('method', '')}".rstrip(": ")]
        lines += self.joint.summary_lines(u)
        rms = self.quality.residual_rms
        if isinstance(rms, dict):
            lines += [f"  residual RMS ({k}): {v:.3g} {u}" for k, v in rms.items()]
        else:
            lines.append(f"  residual RMS: {rms:.3g} {u}")
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)
