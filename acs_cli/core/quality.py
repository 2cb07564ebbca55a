"""One policy for poorly determined results (issue 13): measures, levels and verdicts.

Every estimate carries a few unitless *measures* of how well the data determined it: the
standard deviation of a quantity against its scale, the residual against the rig's size,
the share of frames rejected. Each measure has a :class:`Rule` with two levels:

- past ``warn``, the result is *weak*: it is written, with a warning in the artifact and on
  stderr;
- past ``refuse``, the run stops with exit 3 and advice, unless the user asks for the weak
  result anyway (``--accept-weak``); a result accepted so is marked weak in its artifact and
  in every file exported from it.

A measure that is not finite (a standard deviation the data cannot give) is past both
levels. ``docs/degeneracy.md`` lists the rules; :data:`RULES` holds them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from acs_cli.core.se3 import FloatArray
from acs_cli.errors import DegenerateMotionError

#: The command-line flag that writes a result past a refusal level, marked weak.
ACCEPT_WEAK_FLAG = "--accept-weak"

#: What every refusal message ends with.
OVERRIDE_HINT = f"or rerun with {ACCEPT_WEAK_FLAG} to write the weak result anyway, marked weak"

#: Verdict levels, in order.
LEVELS = ("good", "weak", "refused")


@dataclass(frozen=True)
class Rule:
    """A measure's meaning and its two levels.

    Attributes
    ----------
    key : str
        The measure's name in artifacts (``verdict.measures``).
    what : str
        What the measure is, in words ("the joint's largest std over the rig's size").
    warn, refuse : float
        A value above ``warn`` makes the result weak; above ``refuse``, refused.
    percent : bool
        Print the value as a percentage (a fraction) rather than with ``unit``.
    unit : str
        The value's unit when not a fraction.
    advice : str
        What to do about it.
    alone : bool
        Past its refusal level, the measure refuses the result on its own. False for the
        residual: a large residual with a determined estimate (every std within its levels)
        is noise the stds include, a warning; it refuses only with a diagnosis that finds a
        reading of the inputs that fits much better (:func:`judge`'s ``findings``) or with
        another measure refused.
    """

    key: str
    what: str
    warn: float
    refuse: float
    percent: bool = True
    unit: str = ""
    advice: str = ""
    alone: bool = True

    def format(self, value: float) -> str:
        """``value`` as the messages print it."""
        if not np.isfinite(value):
            return "not determined"
        if self.percent:
            return f"{100 * value:.3g}%"
        return f"{value:.3g} {self.unit}".strip()


JOINT_STD = Rule(
    "joint_std_fraction",
    "the joint's largest standard deviation against the rig's length scale (the joint's "
    "distance from the camera, or a tenth of the camera's travel when larger)",
    0.05,
    0.10,
    advice="record the rig turning about two or more axes by tens of degrees",
)
#: The same measure for a joint declared a hinge: only its line is located, and what
#: locates it is the hinge's own range of angles.
HINGE_STD = dataclasses.replace(
    JOINT_STD,
    advice="record the hinge turning through tens of degrees (its whole working range), with "
    "more frames, while the rig moves",
)
RESIDUAL = Rule(
    "residual_fraction",
    "the joint-constraint residual RMS against the rig's length scale",
    0.03,
    0.25,
    advice="the poses scatter about one joint by that much (pose noise, skin or kinematic "
    "error, or a joint that slips): the stds include it",
    alone=False,
)
REJECTED = Rule(
    "rejected_fraction",
    "the share of frames rejected as outliers",
    0.15,
    0.29,
    advice="many rejected frames mean the model does not fit (a moving joint, a wrong file), "
    "not outliers",
)
ROTATION_STD = Rule(
    "rotation_std_deg",
    "the relative rotation's largest standard deviation",
    2.0,
    10.0,
    percent=False,
    unit="deg",
    advice="record more frames of general motion, or check that the joint file belongs to this rig",
)
TRANSLATION_STD = Rule(
    "translation_std_fraction",
    "the relative translation's largest standard deviation against the rig's length scale",
    0.05,
    0.25,
    advice="record more frames of general motion, or check that the joint file belongs to this rig",
)
SCALE_STD = Rule(
    "scale_std_fraction",
    "the relative scale's standard deviation against the scale",
    0.05,
    0.20,
    advice="record more translation in both cameras, or give a metric joint",
)
FOCAL_STD = Rule(
    "focal_std_fraction",
    "the focal length's standard deviation against the focal length",
    0.01,
    0.05,
    advice="take views of the board at different distances and tilts, filling the image",
)
REPROJECTION = Rule(
    "reprojection_rms_px",
    "the reprojection error RMS",
    0.5,
    5.0,
    percent=False,
    unit="px",
    advice="check --board and --square, and the camera model (--model)",
)

#: Every rule, by key.
RULES: dict[str, Rule] = {
    r.key: r
    for r in (
        JOINT_STD,
        RESIDUAL,
        REJECTED,
        ROTATION_STD,
        TRANSLATION_STD,
        SCALE_STD,
        FOCAL_STD,
        REPROJECTION,
    )
}


@dataclass(frozen=True)
class Measure:
    """One measure of one result.

    Attributes
    ----------
    rule : Rule
    value : float
        NaN or inf when the data cannot give it (counted as refused).
    subject : str
        What it is about ("the joint in A", "camera B").
    """

    rule: Rule
    value: float
    subject: str = ""
    #: past the refusal level of a rule that does not refuse alone, with nothing else to
    #: refuse the result (:func:`judge`): weak, not refused
    capped: bool = False

    @property
    def past_refusal(self) -> bool:
        return not np.isfinite(self.value) or self.value > self.rule.refuse

    @property
    def level(self) -> str:
        """``good``, ``weak`` or ``refused``."""
        if self.past_refusal:
            return "weak" if self.capped else "refused"
        return "weak" if self.value > self.rule.warn else "good"

    def sentence(self) -> str:
        """One sentence: what, its value, the level passed and the advice."""
        limit = self.rule.refuse if self.past_refusal else self.rule.warn
        head = f"{self.subject}: " if self.subject else ""
        said = (
            f"{head}{self.rule.what} is {self.rule.format(self.value)} (above "
            f"{'the refusal level' if self.past_refusal else 'the warning level'} "
            f"{self.rule.format(limit)}); {self.rule.advice}"
        )
        if self.capped:
            said += (
                "; the estimate is still determined (its stds are within their levels), and "
                "no reading of the inputs (quaternion order, inversion, units, clocks) fits "
                "much better: written, as a weak result"
            )
        return said

    def to_plain(self) -> dict[str, Any]:
        return {
            "subject": self.subject,
            "value": float(self.value) if np.isfinite(self.value) else None,
            "warn": self.rule.warn,
            "refuse": self.rule.refuse,
            "level": self.level,
        }


@dataclass(frozen=True)
class Verdict:
    """The measures of one result and what they make of it.

    Attributes
    ----------
    measures : tuple of Measure
    accepted_weak : bool
        A refused result written anyway (``--accept-weak``).
    findings : tuple of str
        What a diagnosis found (a cause that fits much better), said first.
    """

    measures: tuple[Measure, ...]
    accepted_weak: bool = False
    findings: tuple[str, ...] = ()

    @property
    def level(self) -> str:
        """The worst level of the measures (``good`` when there are none)."""
        worst = max((LEVELS.index(m.level) for m in self.measures), default=0)
        return LEVELS[worst]

    @property
    def weak(self) -> bool:
        """The result is past a warning level: exported files are marked."""
        return self.level != "good"

    def warnings(self) -> list[str]:
        """One warning per measure past its warning level (and one for an override)."""
        notes = [*self.findings, *(m.sentence() for m in self.measures if m.level != "good")]
        if self.accepted_weak and self.level == "refused":
            notes.append(
                f"this result is past a refusal level and was written only because of "
                f"{ACCEPT_WEAK_FLAG}: it is marked weak; do not use it where accuracy matters"
            )
        return notes

    def to_plain(self) -> dict[str, Any]:
        """The artifact's ``verdict`` section."""
        return {
            "level": self.level,
            "accepted_weak": bool(self.accepted_weak and self.level == "refused"),
            "measures": {
                f"{m.rule.key}" + (f" ({m.subject})" if m.subject else ""): m.to_plain()
                for m in self.measures
            },
        }


def judge(
    measures: Iterable[Measure], accept_weak: bool = False, findings: Sequence[str] = ()
) -> Verdict:
    """The verdict on ``measures``; raise when one is past its refusal level.

    Parameters
    ----------
    measures : iterable of Measure
    accept_weak : bool
        Write a refused result anyway (``--accept-weak``), marked weak.
    findings : sequence of str
        What a diagnosis found the poses do not fit (:mod:`acs_cli.core.diagnose`): said
        first in the refusal, and kept among the verdict's warnings.

    Returns
    -------
    Verdict
        Its :meth:`Verdict.warnings` go into the artifact and onto stderr.

    Raises
    ------
    DegenerateMotionError
        A measure is past its refusal level and ``accept_weak`` is false (exit 3); the
        message names each such measure with its advice, then :data:`OVERRIDE_HINT`.
    """
    given = tuple(measures)
    alone = [m for m in given if m.past_refusal and m.rule.alone]
    if not findings and not alone:
        # only measures that do not refuse alone are past their levels: the estimate is
        # determined and no diagnosis found a better reading; noise, not a failure
        given = tuple(dataclasses.replace(m, capped=True) if m.past_refusal else m for m in given)
    v = Verdict(given, accepted_weak=accept_weak, findings=tuple(findings))
    refused = [m for m in v.measures if m.level == "refused"]
    if refused and not accept_weak:
        raise DegenerateMotionError(
            "".join(f"{f}. " for f in v.findings)
            + "The result is not determined well enough to use: "
            + "; ".join(m.sentence() for m in refused)
            + f"; {OVERRIDE_HINT}.",
            details={"verdict": v.to_plain(), "findings": list(v.findings)},
        )
    return v


def length_scale(position: FloatArray, T_world_cam: FloatArray) -> float:
    """The rig's length scale as one camera sees it: the joint's distance ``|o|``, or a
    tenth of the camera's RMS travel when that is larger (a joint near the optical centre,
    as on a pan-tilt head, is as well determined as any; its std does not shrink with
    ``|o|``).

    Parameters
    ----------
    position : ndarray, shape (3,)
        The joint in the camera's frame (trajectory units).
    T_world_cam : ndarray, shape (n, 4, 4)
        The camera's poses.

    Returns
    -------
    float
        Trajectory units; at least 1e-12.
    """
    t = np.asarray(T_world_cam, dtype=float)[:, :3, 3]
    travel = float(np.sqrt(np.mean(np.sum((t - t.mean(axis=0)) ** 2, axis=1)))) if len(t) else 0.0
    return max(float(np.linalg.norm(position)), 0.1 * travel, 1e-12)


def largest_std(covariance: FloatArray) -> float:
    """Square root of a covariance's largest eigenvalue (NaN when not finite)."""
    c = np.asarray(covariance, dtype=float)
    if not np.all(np.isfinite(c)):
        return float("nan")
    return float(np.sqrt(max(float(np.linalg.eigvalsh(0.5 * (c + c.T))[-1]), 0.0)))


def std_rule(joint_type: str) -> Rule:
    """The joint-std rule whose advice fits the declared joint type."""
    return HINGE_STD if joint_type == "hinge" else JOINT_STD


def joint_measures(
    position: FloatArray,
    covariance: FloatArray,
    T_world_cam: FloatArray,
    residual_rms: float | None,
    inliers: Sequence[bool] | np.ndarray | None,
    subject: str,
    joint_type: str = "ball",
) -> list[Measure]:
    """The measures of a joint seen from one camera.

    Parameters
    ----------
    position : ndarray, shape (3,)
        The joint in the camera's frame.
    covariance : ndarray, shape (3, 3)
    T_world_cam : ndarray, shape (n, 4, 4)
        The camera's poses (for the length scale).
    residual_rms : float or None
        The joint-constraint residual RMS in the same units, when this camera's fit has one.
    inliers : array of bool, shape (n,), or None
        The frames used.
    subject : str
        "the joint in A", ...
    joint_type : str
        The declared joint (a hinge's advice speaks of hinges, :data:`HINGE_STD`).
    """
    scale = length_scale(position, T_world_cam)
    out = [Measure(std_rule(joint_type), largest_std(covariance) / scale, subject)]
    if residual_rms is not None:
        out.append(Measure(RESIDUAL, float(residual_rms) / scale, subject))
    if inliers is not None and len(inliers):
        out.append(Measure(REJECTED, 1.0 - float(np.mean(inliers)), subject))
    return out


def relative_pose_measures(
    T_b_a: FloatArray,
    covariance: FloatArray,
    scale_b: float,
    phi: float | None = None,
    phi_std: float | None = None,
) -> list[Measure]:
    """The measures of a relative pose ``T_b_a`` with covariance ``(6, 6)`` of (rotation
    perturbation (rad), translation); ``scale_b`` is the rig's length scale in B's units;
    ``phi`` and ``phi_std`` the relative scale under unknown scale."""
    cov = np.asarray(covariance, dtype=float)
    out = [
        Measure(ROTATION_STD, float(np.degrees(largest_std(cov[:3, :3]))), "T_b_a"),
        Measure(
            TRANSLATION_STD,
            largest_std(cov[3:, 3:]) / max(float(np.linalg.norm(T_b_a[:3, 3])), scale_b, 1e-12),
            "T_b_a",
        ),
    ]
    if phi is not None and phi_std is not None:
        out.append(Measure(SCALE_STD, float(phi_std) / max(abs(float(phi)), 1e-300), "phi_ba"))
    return out


def intrinsics_measures(
    camera_matrix: FloatArray, rms_px: float, std: Mapping[str, object] | None
) -> list[Measure]:
    """The measures of a camera calibration: the reprojection RMS (px) and the focal
    lengths' largest std over the focal length (when ``std`` has ``fx`` and ``fy``)."""
    out = [Measure(REPROJECTION, float(rms_px), "the camera")]
    if std and "fx" in std and "fy" in std:
        f = float(min(camera_matrix[0, 0], camera_matrix[1, 1]))
        s = max(float(std["fx"]), float(std["fy"]))  # type: ignore[arg-type]
        out.append(Measure(FOCAL_STD, s / f if f > 0 else float("inf"), "the camera"))
    return out
