"""Render a :class:`~acs_cli.report.model.ReportModel`: the HTML page and its PNG figures.

Pure: no file is read or written (:mod:`acs_cli.stages.report` writes what this returns).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from acs_cli.report import figures as F
from acs_cli.report import verdict as V
from acs_cli.report.html import Page
from acs_cli.report.model import Estimate, ReportModel, RigOfManyView, display_unit

__all__ = ["FIGURE_NAMES", "RenderedReport", "format_number", "render_report"]

#: The figures a report can hold, by key: file name in the figures folder.
FIGURE_NAMES = {
    "trajectory": "rig_trajectory.png",
    "rig": "rig_cameras.png",
    "reference": "rig_reference.png",
    "residuals": "joint_residuals.png",
    "angles": "joint_angles.png",
    "reprojection": "reprojection.png",
    "corners": "corner_errors.png",
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
    std = "fixed" if e.fixed else format_number(e.std, 3)
    return [e.quantity, format_number(e.value, e.digits), std, e.unit, e.source]


def _verdict(page: Page, model: ReportModel) -> None:
    """The verdict section: the overall status, each stage's checks, the thresholds."""
    page.section("verdict", "Verdict: can this calibration be trusted?")
    if not model.verdicts:
        page.note("No stage to judge: the run folder holds no calibration artifact.")
        return
    statuses = [v.status for v in model.verdicts]
    overall = V.worst(statuses)
    counts = ", ".join(f"{statuses.count(s)} {s}" for s in V.STATUSES if s in statuses)
    advice = {
        "pass": "every stage is within the thresholds below.",
        "check": "look at the stages marked check (and their figures below) before use.",
        "fail": "do not use the stages marked fail; see their checks and the warnings.",
    }[overall]
    page.status_line(overall, f"Overall: {overall} ({counts} of {len(statuses)} stages): {advice}")
    page.table(
        ["stage", "verdict", "checks", "source"],
        [
            [v.stage, v.status, "; ".join(c.text() for c in v.checks) or "—", v.source]
            for v in model.verdicts
        ],
        status=1,
    )
    page.paragraph("The thresholds the checks are judged by:")
    page.table(
        ["threshold", "pass", "check", "fail", "what it measures"],
        [[t.label, *t.limits(), t.description] for t in V.THRESHOLDS.values()],
    )


def _finals(page: Page, model: ReportModel) -> None:
    page.section("final", "Final results and exports")
    if model.finals:
        page.paragraph(
            "The final value of each result is the last stage's estimate of it: a bundle "
            "adjustment's when one ran. The estimates table below also lists the others."
        )
        page.table(["result", "final value from", "detail"],
                   [[f.item, f.source, f.detail] for f in model.finals])  # fmt: skip
    else:
        page.paragraph("No intrinsics or joint in the run folder.")
    if model.exported:
        page.paragraph("Exported (files the run folder records):")
        page.items(model.exported)
    else:
        page.paragraph(
            "Exported: no export file is recorded in the run folder (acscal intrinsics "
            "--export writes ROS and OpenCV files beside intrinsics.yaml; acscal export writes "
            "camchains where told)."
        )


def _per_view_rows(model: ReportModel) -> list[list[str]]:
    """Every view's and posed image's RMS, worst first."""
    rows: list[tuple[float, list[str]]] = []
    for cam in model.reprojection:
        C = F.camera_name(cam.camera)
        for name, rms in zip(cam.view_names, cam.view_rms, strict=False):
            rows.append((float(rms), [C, "intrinsics calibration", name, f"{rms:.4f}"]))
        for file, values in sorted(cam.poses.items()):
            names = cam.pose_images.get(file) or [f"#{i}" for i in range(values.size)]
            for name, rms in zip(names, values, strict=False):
                rows.append((float(rms), [C, file, name, f"{rms:.4f}"]))
    rows.sort(key=lambda r: -r[0])
    return [r for _, r in rows]


def _rig(page: Page, rig: RigOfManyView, pngs: dict[str, bytes], dpi: int) -> None:
    """A rig of many cameras: its figure, and which cameras ran from images."""
    pngs["rig"] = F.rig_of_many_figure(
        rig.T_ref_cam, rig.joints, rig.paths, rig.instants, rig.at_instants, rig.reference,
        rig.unit, dpi,
    )  # fmt: skip
    over_time = (
        f"; right, how the rig bends over time: every camera's and joint's position at every "
        f"frame of trajectories/ in {rig.reference}'s frame at that frame (dots; a camera "
        f"rigidly mounted on {rig.reference} stays put, one beyond a ball joint moves on a "
        f"sphere about it), and the rig at {rig.instants.size} of those frames (the "
        "reference instant among them), its links coloured by time"
        if rig.instants.size and rig.at_instants
        else ""
    )
    page.figure(
        pngs["rig"],
        f"The rig of {len(rig.T_ref_cam)} cameras from rig.yaml: left, each camera's frustum "
        "at the reference instant, each ball or hinge joint as a green link through its point, "
        f"rigid pairs dashed{over_time}.",
        "3-D view of the rig of many cameras",
    )
    ran = {c.rsplit("/", 1)[-1] for c in rig.from_images}  # a recording's camera: its body
    given = [c for c in rig.T_ref_cam if c not in ran]
    if not rig.from_images:
        page.paragraph(
            "Every camera's poses were given as a trajectory (none ran from images here): "
            "there are no reprojection errors or image coverage to show."
        )
    elif given:
        were = "was" if len(given) == 1 else "were"
        page.paragraph(
            f"{', '.join(given)} {were} given as poses (no images here): the reprojection "
            "and coverage sections show the cameras that ran from images."
        )


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

    def section(anchor: str, title: str, shown: object) -> bool:
        """Open a section when it has something to show (then True) or a note saying why
        not; a section that does not apply to the run (a rig's without images) is left out."""
        if not shown and not model.notes_of(anchor):
            return False
        page.section(anchor, title)
        notes(anchor)
        return bool(shown)

    _verdict(page, model)
    _finals(page, model)

    page.section("artifacts", "Artifacts")
    page.table(
        ["file", "schema", "created", "method"],
        [[a.file, a.schema, a.created, a.method] for a in model.artifacts],
    )
    for n in model.artifact_notes:
        page.note(n)

    section("trajectory", "The rig and its trajectory", model.rig or model.trajectory)
    if model.rig is not None:
        _rig(page, model.rig, pngs, dpi)
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
        which = f"{d.size} frames"
        if traj.agree_at_reference:
            d = np.delete(d, k)
            which = f"the {d.size} frames besides the reference (where they agree by construction)"
        if d.size:
            page.paragraph(
                f"Joint consistency (distance between the joint as A and as B see it): RMS "
                f"{np.sqrt(np.mean(d**2)):.4g} {shown}, max {d.max():.4g} {shown} over {which}."
            )

    if section("residuals", "Joint-constraint residuals per frame", model.residuals):
        pngs["residuals"] = F.residuals_figure(model.residuals, dpi, model.rig is not None)
        n_rej = sum(int(s.rejected.sum()) for s in model.residuals)
        rig_rows = (
            " Each joint's panels are the rows of its constraint in the rig's solve "
            "(joint_residuals.csv: from the poses, before any bundle adjustment): a ball's or "
            "hinge's point as its two bodies carry it, a hinge's axis, a rigid pair's rotation "
            "and translation; at the reference instant the solve corrects the poses onto the "
            "joints, so the residual there is about zero."
            if model.rig is not None
            else ""
        )
        page.figure(
            pngs["residuals"],
            f"Residual of the joint constraint per frame; frames the estimator rejected as "
            f"outliers are red crosses ({n_rej} in all); dashed: RMS of the frames used."
            + rig_rows
            + (
                " Each panel is scaled to the frames used: a rejected frame far above them is "
                "a red triangle at the top edge, its value beside it."
                if model.rig is not None
                else ""
            ),
            "Joint-constraint residuals per frame",
        )

    if section("angles", "Joint angles per frame", model.angles):
        pngs["angles"] = F.angles_figure(model.angles, dpi)
        rigid = [] if model.rig is None else [j[0] for j in model.rig.joints if j[4] is None]
        source = (
            "acscal trajectory --rig computes angles.csv, here from the run's trajectories/ "
            "(after a bundle adjustment, its per-frame fit where it adjusted)"
            if model.rig is not None
            else "acscal trajectory computes angles.csv, from the recovered trajectory"
        )
        page.figure(
            pngs["angles"],
            "How each ball and hinge joint bent over time, its second body relative to its "
            f"first, zero at the reference instant (dotted), computed as {source}: a hinge's "
            "angle about its axis, a ball's rotation vector; frames the joint rejected as "
            "outliers are red crosses."
            + (f" Rigid joints ({', '.join(rigid)}) have no angle." if rigid else ""),
            "Joint angles per frame",
        )

    if section("reprojection", "Reprojection errors", model.reprojection):
        pngs["reprojection"] = F.reprojection_figure(model.reprojection, dpi)
        page.figure(
            pngs["reprojection"],
            "Left: RMS reprojection error of each view of the intrinsics calibration, one "
            "labelled bar each. Right: RMS reprojection error of each image's board pose (PnP "
            "with the calibrated intrinsics), per poses file.",
            "Reprojection error per view and per camera",
        )
        rows = _per_view_rows(model)
        page.table(
            ["camera", "from", "image", "RMS (px)"],
            rows,
            numeric=(3,),
            collapsed=f"Table of the {len(rows)} views and posed images, worst first",
        )

    if section("corners", "Per-corner reprojection errors", model.corner_errors):
        pngs["corners"] = F.corner_errors_figure(model.corner_errors, dpi)
        page.figure(
            pngs["corners"],
            "Every detected corner of every posed image (corners not seen are left out), "
            "reprojected through its board pose and the camera's intrinsics.yaml. Left: the "
            "error vectors (detected minus projected), a round cloud about zero when the model "
            "fits. Middle: the error against the distance from the principal point, with the "
            "median per ring: errors growing towards the border point to a wrong or too simple "
            "distortion model. Right: the histogram of the error lengths.",
            "Per-corner reprojection errors",
        )

    if section("coverage", "Image coverage of the detected corners", model.coverage):
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
