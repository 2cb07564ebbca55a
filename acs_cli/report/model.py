"""The report as data: a tree of dataclasses built from the artifacts, rendered afterwards.

:func:`acs_cli.stages.report.build_report` reads a run folder into a :class:`ReportModel`
(no drawing); :func:`acs_cli.report.render.render_report` turns the model into the HTML
page and its PNG figures (no file access). Lengths are in each section's ``unit``;
figure data holds arrays (shapes in each class).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from acs_cli.core.se3 import FloatArray
from acs_cli.report.figures import (
    AngleSeries,
    CameraView,
    CornerErrorData,
    CoverageData,
    ReprojectionData,
    ResidualSeries,
)
from acs_cli.report.verdict import StageVerdict

__all__ = [
    "ArtifactRow",
    "Estimate",
    "FinalChoice",
    "ReportModel",
    "RigOfManyView",
    "RigTrajectory",
    "SectionNotes",
    "display_unit",
]


def display_unit(unit: str) -> tuple[float, str]:
    """The factor and unit lengths are shown in: metres as millimetres, others as they are."""
    return (1000.0, "mm") if unit == "m" else (1.0, unit)


@dataclass(frozen=True)
class ArtifactRow:
    """One artifact found in the run folder: its file (relative to the folder), schema,
    creation date and method, as recorded."""

    file: str
    schema: str
    created: str
    method: str


@dataclass(frozen=True)
class Estimate:
    """One estimated quantity with its one-sigma standard deviation.

    Attributes
    ----------
    quantity : str
        What it is, e.g. ``"joint in A (o_a) x"``.
    value : float or None
    std : float or None
        One sigma, in ``unit`` (None: not known).
    unit : str
    source : str
        The artifact it comes from (relative to the run folder).
    digits : int
        Significant digits of the value.
    fixed : bool
        Held at its value by the estimator (shown as "fixed", not as a std).
    """

    quantity: str
    value: float | None
    std: float | None
    unit: str
    source: str
    digits: int = 6
    fixed: bool = False


@dataclass(frozen=True)
class FinalChoice:
    """Which artifact holds the final value of a result, and what was exported of it.

    Attributes
    ----------
    item : str
        E.g. ``"intrinsics of camera A"``, ``"joint"``.
    source : str
        The artifact and section holding the final value.
    detail : str
        Its key numbers, or why it is final.
    """

    item: str
    source: str
    detail: str


@dataclass(frozen=True)
class RigTrajectory:
    """The rig over time in camera A's frame at the reference instant.

    Attributes
    ----------
    title : str
        Where it comes from.
    unit : str
        Length unit of the translations.
    T_r_a, T_r_b : ndarray, shape (n, 4, 4)
        Camera A's and B's poses in the reference frame.
    joint_a, joint_b : ndarray, shape (n, 3)
        The joint as A and as B locate it.
    consistency : ndarray, shape (n,)
        ``|joint_a - joint_b|`` per frame, ``unit``.
    x : ndarray, shape (n,)
        A's timestamps (s) or frame numbers.
    rejected : ndarray of bool, shape (n,)
        Frames the estimator rejected as outliers.
    reference : int
        The reference frame (``T_r_a[reference]`` is the identity).
    position_in_a : ndarray, shape (3,)
        The joint in camera A's frame.
    agree_at_reference : bool
        The joint as A and as B see it coincide at the reference to rounding, by construction
        (relpose's reference pose corrected by the joint), so ``consistency[reference]`` is
        no measurement.
    """

    title: str
    unit: str
    T_r_a: FloatArray
    T_r_b: FloatArray
    joint_a: FloatArray
    joint_b: FloatArray
    consistency: FloatArray
    x: FloatArray
    rejected: np.ndarray
    reference: int
    position_in_a: FloatArray
    agree_at_reference: bool = False


@dataclass(frozen=True)
class RigOfManyView:
    """A rig of many cameras (``rig.yaml``) for the report: where each camera and joint is.

    Attributes
    ----------
    unit : str
        Length unit (the reference camera's).
    reference : str
        The reference camera.
    T_ref_cam : dict of str to ndarray, shape (4, 4)
        Each camera's pose in the reference camera's frame at the reference instant.
    joints : list of (name, type, p, q, point (3,) or None)
        Each edge; ``point`` is the joint (ball centre or hinge point) in the reference frame.
    paths : dict of str to ndarray, shape (n, 3)
        Each camera's and joint's position (``trajectories/*.tum``) at each of the reference
        camera's ``n`` instants, in the reference camera's frame at that instant (how the
        rig bends about it; NaN where it has no pose).
    instants : ndarray, shape (k,)
        A few times (the reference instant among them) at which the figure draws the rig.
    at_instants : dict of str to ndarray, shape (k, 3)
        ``paths`` at ``instants``.
    from_images : list of str
        The cameras that ran from images here (their reprojection errors and coverage are
        shown); the others were given as poses.
    """

    unit: str
    reference: str
    T_ref_cam: dict[str, FloatArray]
    joints: list[tuple[str, str, str, str, FloatArray | None]]
    paths: dict[str, FloatArray] = field(default_factory=dict)
    instants: FloatArray = field(default_factory=lambda: np.zeros(0))
    at_instants: dict[str, FloatArray] = field(default_factory=dict)
    from_images: list[str] = field(default_factory=list)


@dataclass
class SectionNotes:
    """Notes a section shows in place of what it could not draw, in order."""

    notes: list[str] = field(default_factory=list)


@dataclass
class ReportModel:
    """Everything the report shows, before any drawing.

    Attributes
    ----------
    title, meta : str
        The page's title and the line under it.
    views : tuple of CameraView
        How to draw camera A's and B's frustums.
    artifacts : list of ArtifactRow
    artifact_notes : list of str
        Artifacts that could not be read.
    trajectory : RigTrajectory or None
    rig : RigOfManyView or None
        A rig of many cameras (``rig.yaml``).
    residuals : list of ResidualSeries
        One panel per joint-stage camera (or pair) and one for relpose; for a rig, one per
        joint and residual kind (point, axis, rotation, translation).
    angles : list of AngleSeries
        A rig's ball and hinge joints' angles over time, one panel per joint.
    reprojection : list of ReprojectionData
    coverage : list of CoverageData
    estimates : list of Estimate
    verdicts : list of StageVerdict
        Each stage's pass, check or fail, in the run's order.
    finals : list of FinalChoice
        Where the final intrinsics and joint are.
    exported : list of str
        The export files the run folder records, each with what it holds.
    corner_errors : list of CornerErrorData
        Per-corner reprojection errors per camera.
    warnings : list of str
        ``source: text`` of every warning.
    notes : list of str
        Every section skipped and every artifact not read, in order.
    section_notes : dict of str to SectionNotes
        The notes shown in each section (by anchor).
    """

    title: str
    meta: str
    views: tuple[CameraView, CameraView] = (CameraView(), CameraView())
    artifacts: list[ArtifactRow] = field(default_factory=list)
    artifact_notes: list[str] = field(default_factory=list)
    trajectory: RigTrajectory | None = None
    rig: RigOfManyView | None = None
    residuals: list[ResidualSeries] = field(default_factory=list)
    angles: list[AngleSeries] = field(default_factory=list)
    reprojection: list[ReprojectionData] = field(default_factory=list)
    coverage: list[CoverageData] = field(default_factory=list)
    estimates: list[Estimate] = field(default_factory=list)
    verdicts: list[StageVerdict] = field(default_factory=list)
    finals: list[FinalChoice] = field(default_factory=list)
    exported: list[str] = field(default_factory=list)
    corner_errors: list[CornerErrorData] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    section_notes: dict[str, SectionNotes] = field(default_factory=dict)

    def skip(self, section: str, text: str) -> None:
        """Record that part of ``section`` was skipped, and why."""
        self.notes.append(text)
        self.section_notes.setdefault(section, SectionNotes()).notes.append(text)

    def notes_of(self, section: str) -> list[str]:
        """The notes ``section`` shows."""
        sec = self.section_notes.get(section)
        return [] if sec is None else list(sec.notes)
