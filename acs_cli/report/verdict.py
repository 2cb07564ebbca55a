"""The report's verdict: each stage of a run marked pass, check or fail against stated
thresholds.

:data:`THRESHOLDS` is the one table of limits (the report prints it under the verdict).
A stage's :class:`StageVerdict` holds its :class:`Check` s, each a number classified by
:func:`classify`; the stage's status is its worst check's. The functions here take numbers
(no artifacts): :mod:`acs_cli.stages.report` reads the artifacts and calls them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Literal

from acs_cli.core.quality import JOINT_STD, LEVELS, REPROJECTION, RESIDUAL

__all__ = [
    "COVERAGE_GRID",
    "STATUSES",
    "THRESHOLDS",
    "Check",
    "StageVerdict",
    "Status",
    "Threshold",
    "artifact_verdict_check",
    "classify",
    "expected_joint_residual",
    "joint_checks",
    "reprojection_checks",
    "worst",
]

#: Cells across and down of the grid over the image that image coverage counts.
COVERAGE_GRID = (16, 12)

Status = Literal["pass", "check", "fail"]
#: The statuses from best to worst.
STATUSES: tuple[Status, ...] = ("pass", "check", "fail")


@dataclass(frozen=True)
class Threshold:
    """The limits of one quantity.

    Attributes
    ----------
    label : str
        What is measured, as the report names it.
    unit : str
        The unit the values are shown in (after ``scale``).
    pass_limit : float
        Pass up to this value (from this value when ``higher_is_better``), in stored units.
    fail_limit : float or None
        Check up to this value (from it when ``higher_is_better``), fail beyond it; None:
        never fail, only check.
    higher_is_better : bool
        True for a quantity that should be large (image coverage).
    scale : float
        Factor from stored units to shown ones (100 for a fraction shown in %).
    description : str
        Why the limits are where they are.
    """

    label: str
    unit: str
    pass_limit: float
    fail_limit: float | None
    higher_is_better: bool = False
    scale: float = 1.0
    description: str = ""

    def show(self, value: float) -> str:
        """``value`` in shown units with the unit, e.g. ``"38%"`` or ``"0.42 px"``."""
        v = value * self.scale
        text = f"{v:.3g}"
        return f"{text}%" if self.unit == "%" else f"{text} {self.unit}".rstrip()

    def limits(self) -> tuple[str, str, str]:
        """The pass, check and fail ranges as text."""
        good, bad = (">=", "<") if self.higher_is_better else ("<=", ">")
        p = f"{good} {self.show(self.pass_limit)}"
        if self.fail_limit is None:
            return p, f"{bad} {self.show(self.pass_limit)}", "never"
        return p, f"{good} {self.show(self.fail_limit)}", f"{bad} {self.show(self.fail_limit)}"


#: The limits of every check, by key. Ratios are stored as fractions and shown in %.
THRESHOLDS: dict[str, Threshold] = {
    "reprojection_rms_px": Threshold(
        "reprojection RMS",
        "px",
        REPROJECTION.warn,
        REPROJECTION.refuse,
        description="RMS distance between the detected corners and the calibrated model's "
        "projection of the board. Sharp checkerboard corners reach 0.1-0.3 px; above 1 px a "
        "detection, the camera model or the board's geometry is likely wrong. The limits are "
        "the warning and refusal levels of docs/degeneracy.md (reprojection_rms_px).",
    ),
    "coverage": Threshold(
        "image coverage",
        "%",
        0.5,
        0.25,
        higher_is_better=True,
        scale=100.0,
        description=f"Share of the cells of a {COVERAGE_GRID[0]}x{COVERAGE_GRID[1]} grid over "
        "the image holding at least one detected corner (every posed image of the camera). "
        "Under half, the distortion outside the covered part is extrapolated.",
    ),
    "joint_residual_over_noise": Threshold(
        "joint residual / expected from the pose noise",
        "x",
        2.0,
        4.0,
        description="RMS of the joint-constraint residual over the residual the estimated "
        "pose noise explains (sqrt(3 sigma_t^2 + 2 (sigma_r d)^2) per camera, d the joint's "
        "distance). About 1 when the joint model fits; well above, the joint moved, slipped or "
        "is not a ball joint, or the poses carry errors the noise levels do not describe.",
    ),
    "joint_residual_over_distance": Threshold(
        "joint residual / joint distance",
        "%",
        RESIDUAL.warn,
        RESIDUAL.refuse,
        scale=100.0,
        description="RMS of the joint-constraint residual relative to the joint's distance "
        "from the camera. The limits are the warning and refusal levels of the one policy "
        "for weak results (docs/degeneracy.md, residual_fraction).",
    ),
    "joint_std_over_distance": Threshold(
        "joint std / joint distance",
        "%",
        JOINT_STD.warn,
        JOINT_STD.refuse,
        scale=100.0,
        description="The joint's largest one-sigma uncertainty (from its covariance) relative "
        "to its distance from the camera: above a few percent the motion did not excite the "
        "joint enough (more rotation about it is needed). The limits are the warning and "
        "refusal levels of docs/degeneracy.md (joint_std_fraction), whose scale is also at "
        "least a tenth of the camera's travel: for a joint near the optical centre the "
        "artifact's own verdict is the one to read.",
    ),
    "artifact_verdict": Threshold(
        "the artifact's own verdict (0 good, 1 weak, 2 refused and written with --accept-weak)",
        "",
        0.0,
        1.0,
        description="The verdict section each joint, relpose and rig artifact carries "
        "(docs/degeneracy.md): weak past a warning level, refused past a refusal level.",
    ),
    "warnings": Threshold(
        "warnings",
        "",
        0.0,
        None,
        description="Warnings the stage's artifacts record (listed under Warnings). Any "
        "warning asks for a look; warnings alone never fail a stage.",
    ),
}


def classify(key: str, value: float) -> Status:
    """Pass, check or fail of ``value`` against ``THRESHOLDS[key]`` (non-finite: fail).

    Parameters
    ----------
    key : str
        A key of :data:`THRESHOLDS`.
    value : float
        In the threshold's stored units (fractions for ratios).

    Returns
    -------
    {"pass", "check", "fail"}

    Raises
    ------
    KeyError
        An unknown ``key``.
    """
    t = THRESHOLDS[key]
    if not math.isfinite(value):
        return "fail"
    sign = -1.0 if t.higher_is_better else 1.0
    if sign * value <= sign * t.pass_limit:
        return "pass"
    if t.fail_limit is None or sign * value <= sign * t.fail_limit:
        return "check"
    return "fail"


def worst(statuses: Iterable[Status]) -> Status:
    """The worst of ``statuses`` (pass when there is none)."""
    return max(statuses, key=STATUSES.index, default="pass")


@dataclass(frozen=True)
class Check:
    """One number of a stage against its threshold.

    Attributes
    ----------
    key : str
        The threshold's key in :data:`THRESHOLDS`.
    value : float
        In the threshold's stored units.
    subject : str
        What it is of (``"camera A"``, ``"joint in B"``), or empty.
    """

    key: str
    value: float
    subject: str = ""

    @property
    def status(self) -> Status:
        """:func:`classify` of the value."""
        return classify(self.key, self.value)

    def text(self) -> str:
        """E.g. ``"camera A: image coverage 38% (check)"``."""
        t = THRESHOLDS[self.key]
        who = f"{self.subject}: " if self.subject else ""
        return f"{who}{t.label} {t.show(self.value)} ({self.status})"


@dataclass(frozen=True)
class StageVerdict:
    """A stage's verdict: its checks, and the artifact they come from.

    Attributes
    ----------
    stage : str
        E.g. ``"intrinsics A"``, ``"bundle adjustment (relpose.yaml) B"``.
    source : str
        The artifact (relative to the run folder).
    checks : list of Check
    """

    stage: str
    source: str
    checks: list[Check] = field(default_factory=list)

    @property
    def status(self) -> Status:
        """The worst check's status (pass without checks)."""
        return worst(c.status for c in self.checks)


def expected_joint_residual(
    sigma_trans: float, sigma_rot_deg: float, distance: float, cameras: int = 1
) -> float:
    """The RMS joint residual (3-D) that pose noise alone explains.

    A camera pose with per-axis translation noise ``sigma_trans`` and rotation noise
    ``sigma_rot_deg`` (per axis, on the right) moves a point at ``distance`` by
    ``3 sigma_t^2 + 2 (sigma_r distance)^2`` in mean square; ``cameras`` such poses add up.

    Parameters
    ----------
    sigma_trans : float
        Length unit.
    sigma_rot_deg : float
        Degrees.
    distance : float
        The joint's distance from the camera, length unit.
    cameras : int
        The poses the residual combines (1: fixed joint; 2: a pair).

    Returns
    -------
    float
        Length unit.
    """
    s_r = math.radians(sigma_rot_deg) * distance
    return math.sqrt(cameras * (3.0 * sigma_trans**2 + 2.0 * s_r**2))


def reprojection_checks(
    rms_px: float | None, coverage: float | None = None, subject: str = ""
) -> list[Check]:
    """The checks of a stage that fits corners: its RMS and its image coverage (each when
    known)."""
    out = []
    if rms_px is not None:
        out.append(Check("reprojection_rms_px", rms_px, subject))
    if coverage is not None:
        out.append(Check("coverage", coverage, subject))
    return out


def artifact_verdict_check(level: str | None, subject: str = "") -> list[Check]:
    """The check of an artifact's own ``verdict.level`` (none for an artifact without one)."""
    if level is None:
        return []
    return [Check("artifact_verdict", float(LEVELS.index(level)), subject)]


def joint_checks(
    residual_rms: float | None,
    distance: float,
    std: Iterable[float] | None = None,
    noise: tuple[float, float] | None = None,
    cameras: int = 1,
    subject: str = "",
) -> list[Check]:
    """The checks of a joint: residual against noise and distance, std against distance.

    Parameters
    ----------
    residual_rms : float or None
        RMS of the joint-constraint residual (length unit), None when not recorded.
    distance : float
        The joint's distance from the camera (same unit); no check without it (<= 0).
    std : iterable of float, optional
        The stds whose norm is judged (the report passes the largest std alone).
    noise : (sigma_trans, sigma_rot_deg), optional
        The estimated pose noise (:func:`expected_joint_residual`).
    cameras : int
        The poses each residual combines.
    subject : str

    Returns
    -------
    list of Check
    """
    out: list[Check] = []
    if not distance > 0.0:
        return out
    if residual_rms is not None:
        if noise is not None:
            expected = expected_joint_residual(noise[0], noise[1], distance, cameras)
            if expected > 0.0:
                out.append(Check("joint_residual_over_noise", residual_rms / expected, subject))
        out.append(Check("joint_residual_over_distance", residual_rms / distance, subject))
    if std is not None:
        s = math.sqrt(sum(float(x) ** 2 for x in std))
        out.append(Check("joint_std_over_distance", s / distance, subject))
    return out
