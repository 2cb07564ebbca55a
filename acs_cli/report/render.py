"""Render a :class:`~acs_cli.report.model.ReportModel`: the HTML page and its PNG figures.

Pure: no file is read or written (:mod:`acs_cli.stages.report` writes what this returns).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acs_cli.report import figures as F
from acs_cli.report.html import Page
from acs_cli.report.model import Estimate, ReportModel, display_unit

__all__ = ["FIGURE_NAMES", "RenderedReport", "format_number", "render_report"]

#: The figures a report can hold, by key: file name in the figures folder.
FIGURE_NAMES = {
    "trajectory": "rig_trajectory.png",
    "rig": "rig_cameras.png",
    "reference": "rig_reference.png",
    "residuals": "joint_residuals.png",
    "reprojection": "reprojection.png",
    "coverage": "coverage.png",
}


@dataclass(frozen=True)
class RenderedReport:
    """The page and its figures.

    Attributes
    ----------
    html : str
        The self-contained HTML document.
    pngs : dict of str to bytes
        The figures by key of :data:`FIGURE_NAMES`, in the page's order.
    """

    html: str
    pngs: dict[str, bytes]


def format_number(x: float | None, digits: int = 6) -> str:
    """``x`` with ``digits`` significant digits, or an em dash for None."""
    return "—" if x is None else f"{float(x):.{digits}g}"


def _estimate_row(e: Estimate) -> list[str]:
    return [e.quantity, format_number(e.value, e.digits), format_number(e.std, 3), e.unit, e.source]


def render_report(model: ReportModel, dpi: int = 100, max_frustums: int = 25) -> RenderedReport:
    """Draw the figures and assemble the page.

    Parameters
    ----------
    model : ReportModel
    dpi : int
        Resolution of the figures.
    max_frustums : int
        At most this many camera frustums per camera in the trajectory view.

    Returns
    -------
    RenderedReport
    """
    page = Page(model.title, model.meta)
    pngs: dict[str, bytes] = {}

    def notes(section: str) -> None:
        for n in model.notes_of(section):
            page.note(n)

    page.section("artifacts", "Artifacts")
    page.table(
        ["file", "schema", "created", "method"],
        [[a.file, a.schema, a.created, a.method] for a in model.artifacts],
    )
    for n in model.artifact_notes:
        page.note(n)

    page.section("trajectory", "The rig and its trajectory")
    notes("trajectory")
    if model.rig is not None:
        rig = model.rig
        pngs["rig"] = F.rig_of_many_figure(rig.T_ref_cam, rig.joints, rig.paths, rig.unit, dpi)
        page.figure(
            pngs["rig"],
            f"The rig of {len(rig.T_ref_cam)} cameras from rig.yaml: each camera's frustum at "
            "the reference instant, each ball or hinge joint as a green link through its point, "
            "rigid pairs dashed; right, every camera's and joint's path from trajectories/.",
            "3-D view of the rig of many cameras",
        )
    traj = model.trajectory
    if traj is not None:
        scale, shown = display_unit(traj.unit)
        pngs["trajectory"] = F.rig_trajectory_figure(
            traj.T_r_a,
            traj.T_r_b,
            traj.joint_a,
            traj.joint_b,
            traj.reference,
            traj.unit,
            model.views,
            max_frustums,
            dpi,
        )
        page.figure(
            pngs["trajectory"],
            f"Both cameras (frustums: A blue, B orange) and the joint's path (green: as A "
            f"sees it; crosses: as B sees it) over {traj.T_r_a.shape[0]} paired frames, in "
            f"camera A's frame at the reference instant; grey lines link each camera to the "
            f"joint. Source: {traj.title}.",
            "3-D view of the rig's trajectory",
        )
        k = traj.reference  # T_r_a[k] is the identity: T_r_b[k] is T_a_b at the reference
        pngs["reference"] = F.rig_reference_figure(
            traj.T_r_b[k], traj.position_in_a, traj.joint_b[k], traj.unit, model.views, dpi
        )
        page.figure(
            pngs["reference"],
            "The rig at the reference instant, in camera A's frame: camera B's pose T_a_b and "
            "the joint as each camera locates it.",
            "The rig at the reference instant",
        )
        d = traj.consistency * scale
        page.paragraph(
            f"Joint consistency (distance between the joint as A and as B see it): RMS "
            f"{np.sqrt(np.mean(d**2)):.4g} {shown}, max {d.max():.4g} {shown} over "
            f"{d.size} frames."
        )

    page.section("residuals", "Joint-constraint residuals per frame")
    notes("residuals")
    if model.residuals:
        pngs["residuals"] = F.residuals_figure(model.residuals, dpi)
        n_rej = sum(int(s.rejected.sum()) for s in model.residuals)
        page.figure(
            pngs["residuals"],
            f"Residual of the joint constraint per frame; frames the estimator rejected as "
            f"outliers are red crosses ({n_rej} in all); dashed: RMS of the frames used.",
            "Joint-constraint residuals per frame",
        )

    page.section("reprojection", "Reprojection errors")
    notes("reprojection")
    if model.reprojection:
        pngs["reprojection"] = F.reprojection_figure(model.reprojection, dpi)
        page.figure(
            pngs["reprojection"],
            "Left: RMS reprojection error of each view of the intrinsics calibration. Right: "
            "RMS reprojection error of each image's board pose (PnP with the calibrated "
            "intrinsics), per poses file.",
            "Reprojection error per view and per camera",
        )

    page.section("coverage", "Image coverage of the detected corners")
    notes("coverage")
    if model.coverage:
        pngs["coverage"] = F.coverage_figure(model.coverage, dpi=dpi)
        page.figure(
            pngs["coverage"],
            "Where in each camera's image the board's corners were detected (every posed image "
            "of the run): corners per cell of a 16x12 grid, each corner a white dot. Empty "
            "borders mean the lens distortion there is extrapolated.",
            "Image coverage of the detected corners",
        )

    page.section("estimates", "Estimates and standard deviations")
    notes("estimates")
    if model.estimates:
        page.table(
            ["quantity", "value", "std (1 sigma)", "unit", "source"],
            [_estimate_row(e) for e in model.estimates],
            numeric=(1, 2),
        )

    page.section("warnings", "Warnings")
    if model.warnings:
        page.items(model.warnings, "warn")
    else:
        page.paragraph("No warnings.")
    if model.notes:
        page.section("notes", "Sections skipped")
        page.items(model.notes)
    return RenderedReport(page.render(), {k: pngs[k] for k in FIGURE_NAMES if k in pngs})
