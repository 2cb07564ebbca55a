"""Commands that show a calibration: ``acscal trajectory`` and ``acscal report``.

Thin Typer commands over :mod:`acs_cli.stages.trajectory` and :mod:`acs_cli.stages.report`;
:func:`register` adds them to the ``acscal`` app.
"""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from acs_cli.cli.help_format import AcsCommand
from acs_cli.cli.output import JsonOpt, artifact_result, emit, out, warn
from acs_cli.errors import InputError

__all__ = ["positive_seconds", "register", "report", "trajectory"]


def positive_seconds(value: float | None) -> float | None:
    """``--max-dt``'s check: a positive number of seconds (a pair's largest time
    difference; 0 would pair only identical timestamps, NaN nothing)."""
    if value is not None and not value > 0:
        raise typer.BadParameter(f"must be a positive number of seconds, got {value}")
    return value


class TrajFormat(str, Enum):
    auto = "auto"
    tum = "tum"
    kitti = "kitti"
    colmap = "colmap"
    npz = "npz"


class PairBy(str, Enum):
    auto = "auto"
    timestamp = "timestamp"
    by_index = "index"


FormatAOpt = Annotated[TrajFormat, typer.Option("--format-a", help="Format of --poses-a.")]
FormatBOpt = Annotated[TrajFormat, typer.Option("--format-b", help="Format of --poses-b.")]


def trajectory(
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            help="Folder for cam_a.tum, cam_b.tum, joint.tum, trajectory.yaml (a rig: "
            "<camera>.tum and <joint>.tum).",
        ),
    ],
    relpose: Annotated[
        Path | None, typer.Option("--relpose", help="relpose.yaml from `acscal relpose`.")
    ] = None,
    poses_a: Annotated[
        Path | None, typer.Option("--poses-a", help="Camera A's trajectory (as given to relpose).")
    ] = None,
    poses_b: Annotated[
        Path | None, typer.Option("--poses-b", help="Camera B's trajectory (as given to relpose).")
    ] = None,
    rig: Annotated[
        Path | None,
        typer.Option(
            "--rig",
            help="rig.yaml from `acscal run` on a rig config: every camera and joint (instead "
            "of --relpose, --poses-a, --poses-b).",
        ),
    ] = None,
    poses: Annotated[
        list[str] | None,
        typer.Option(
            "--poses",
            help="With --rig: a camera's trajectory as NAME=FILE (default: the file rig.yaml "
            "records).",
        ),
    ] = None,
    joint: Annotated[
        Path | None,
        typer.Option(
            "--joint",
            help="joint.yaml whose joint to use (default: the joint relpose.yaml estimated "
            "with the relative pose).",
        ),
    ] = None,
    format_a: FormatAOpt = TrajFormat.auto,
    format_b: FormatBOpt = TrajFormat.auto,
    pair_by: Annotated[
        PairBy,
        typer.Option(
            "--pair-by",
            help="Pair A's and B's samples by timestamp or index (default: as relpose did).",
        ),
    ] = PairBy.auto,
    max_dt: Annotated[
        float | None,
        typer.Option(
            "--max-dt",
            help="Largest timestamp difference of a pair, seconds (default: as relpose did).",
            callback=positive_seconds,
        ),
    ] = None,
    euler: Annotated[
        str,
        typer.Option(
            "--euler",
            help="Euler sequence of a ball joint's angles in angles.csv: XYZ ... ZYZ "
            "(upper case intrinsic, lower case extrinsic).",
        ),
    ] = "ZXY",
    zero_at: Annotated[
        float | None,
        typer.Option(
            "--zero-at",
            help="The time (camera A's, or the reference camera's; seconds, or frame numbers "
            "for trajectories without times) whose nearest frame is each joint's zero angle in "
            "angles.csv (default: the reference instant).",
        ),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Recover the ACS's trajectory in one frame: camera A's at the reference instant.

    Writes camera A's and camera B's poses and the joint's path as TUM files (T_world_X,
    world = camera A at relpose.yaml's reference instant; the joint's orientation is camera
    A's), angles.csv with the joint's angles per frame (a hinge's angle about its axis, a
    ball's rotation vector and Euler angles: B turning relative to A since the reference
    instant, each with its std), and trajectory.yaml with the joint constraint's consistency
    per frame (distance between the joint as A and as B see it). Under unknown scale B is
    brought to A's units.

    Example:

        acscal trajectory --joint joint.yaml --relpose relpose.yaml --poses-a a.tum \\
            --poses-b b.tum -o trajectory/

        acscal trajectory --rig out/rig.yaml -o trajectory/
    """
    if rig is not None:
        if relpose is not None or poses_a is not None or poses_b is not None:
            raise InputError(
                "--rig replaces --relpose, --poses-a and --poses-b: give one or the other"
            )
        _rig_trajectory(rig, poses or [], output, euler, zero_at)
        return
    if relpose is None or poses_a is None or poses_b is None:
        missing = [n for n, v in (("--relpose", relpose), ("--poses-a", poses_a),
                                   ("--poses-b", poses_b)) if v is None]  # fmt: skip
        raise InputError(f"missing {', '.join(missing)} (or give --rig rig.yaml)")
    from rich.table import Table

    from acs_cli.stages.trajectory import TrajectoryConfig, run_trajectory

    cfg = TrajectoryConfig(
        format_a=format_a.value,
        format_b=format_b.value,
        pair_by=pair_by.value,
        max_dt=max_dt,
        euler=euler,
        zero_at=zero_at,
    )
    run = run_trajectory(relpose, poses_a, poses_b, output, cfg, joint=joint)
    rec = run.estimate
    cons = run.artifact["consistency"]
    unit = rec.length_unit
    table = Table(title="ACS trajectory (world = camera A at the reference)", title_justify="left")
    table.add_column("quantity")
    table.add_column("value")
    table.add_row("frames", str(rec.trajectory.n))
    ref = run.artifact["reference"]
    table.add_row("reference", f"frame {ref['index']} (A at {ref['timestamp_a']:.6g})")
    if rec.trajectory.phi_ba != 1.0:
        table.add_row("phi_ba (B units per A unit)", f"{rec.trajectory.phi_ba:.5f}")
    table.add_row(f"joint consistency RMS ({unit})", f"{cons['rms']:.4g}")
    table.add_row(f"joint consistency max ({unit})", f"{cons['max']:.4g}")
    table.add_row("rejected frames (by relpose)", str(int(rec.rejected.sum())))
    ang = run.artifact["angles"]
    if "angle_range_deg" in ang:
        lo, hi = ang["angle_range_deg"]
        table.add_row("hinge angle range (deg)", f"{lo:.2f} to {hi:.2f}")
        table.add_row("hinge wobble RMS (deg)", f"{ang['wobble_rms_deg']:.3f}")
    out.print(table)
    warn(run.warnings)
    tums = [output / n for n in run.artifact["outputs"].values()]
    out.print(f"wrote {', '.join(map(str, tums))}")
    out.print(f"wrote {run.output}")
    emit(artifact_result(run.artifact), written=[*tums, run.output], warnings=run.warnings)


def report(
    run_dir: Annotated[
        Path, typer.Argument(help="A run folder (what `acscal run CONFIG` writes).")
    ],
    output: Annotated[
        Path | None,
        typer.Option(
            "-o",
            "--output",
            help="HTML file to write (default RUN_DIR/report.html); figures go to "
            "<name>_files/ beside it.",
        ),
    ] = None,
    json_out: JsonOpt = False,
) -> None:
    """Write a self-contained HTML report of a calibration run, with its figures as PNG.

    The rig and its trajectory in 3D, the joint constraint's residuals per frame (rejected
    frames marked), the reprojection errors and image coverage of each camera, every
    estimate with its standard deviation and units, and every warning of the run. Sections
    whose artifact is missing are skipped with a note.

    Example:

        acscal report demo_out/run_fixed_joint -o report.html
    """
    from acs_cli.stages.report import run_report

    target = output if output is not None else run_dir / "report.html"
    run = run_report(run_dir, target)
    warn(run.notes, prefix="note")
    out.print(f"wrote {run.output} ({len(run.figures)} figures in {run.figures_dir})")
    emit(
        {"output": run.output, "figures_dir": run.figures_dir, "notes": run.notes},
        written=[run.output, *run.figures],
        warnings=run.warnings,
    )


def _rig_trajectory(
    rig_file: Path, poses: list[str], output: Path, euler: str, zero_at: float | None
) -> None:
    """``acscal trajectory --rig``: every camera and joint of a rig in the reference frame."""
    from acs_cli.core.angles import check_euler_sequence
    from acs_cli.io.angles import write_angles_csv
    from acs_cli.io.rig import RigArtifact
    from acs_cli.io.trajectory import read_trajectory, write_tum
    from acs_cli.io.verdict import weak_marks
    from acs_cli.stages.rig import check_poses_fit_rig, trajectories_from_rig
    from acs_cli.stages.trajectory import rig_angles

    check_euler_sequence(euler, "--euler ")  # before anything is written
    art = RigArtifact.load(rig_file)
    files: dict[str, Path] = {}
    for c, cam in art.cameras.items():
        if cam.T_cam_ref is None:  # a body seen only in another recording
            continue
        key = f"poses_{art.reference_recording}_{c}" if art.reference_recording else f"poses_{c}"
        rec = art.inputs.get(key)
        if isinstance(rec, dict) and rec.get("path"):
            p = Path(str(rec["path"]))
            files[c] = p if p.is_file() or p.is_absolute() else rig_file.parent / p
    for item in poses:
        name, sep, path = item.partition("=")
        if not sep or name not in art.cameras:
            raise InputError(
                f"--poses {item!r}: write it as NAME=FILE with NAME one of {', '.join(art.cameras)}"
            )
        files[name] = Path(path)
    trajectories = {c: read_trajectory(p) for c, p in files.items()}
    paths = trajectories_from_rig(art, trajectories)
    check_poses_fit_rig(art, paths)  # before anything is written
    angles = rig_angles(art, paths, euler, zero_at)
    marks = weak_marks(rig_file.name, art.verdict)
    warn(marks)
    if art.bundle_adjustment:
        warn(
            [
                f"{rig_file.name} was refined by a bundle adjustment: these are the measured "
                "poses mapped by its calibration; the run's own trajectories/ hold the "
                "bundle's per-frame fit at the instants it adjusted"
            ],
            prefix="note",
        )
    written = []
    for name, (times, T) in paths.items():
        f = output / f"{name}.tum"
        write_tum(f, times, T, note="; ".join(marks) or None)
        written.append(f.name)
    if angles:
        write_angles_csv(output / "angles.csv", angles)
        written.append("angles.csv")
    out.print(
        f"wrote {len(written)} trajectories to {output} ({', '.join(written)}), in "
        f"{art.reference_camera}'s frame at frame {art.reference_frame} ({art.length_unit})"
    )
    emit(
        {
            "reference_camera": art.reference_camera,
            "reference_frame": art.reference_frame,
            "length_unit": art.length_unit,
            "trajectories": {name: output / f"{name}.tum" for name in paths},
            "angles": None if not angles else output / "angles.csv",
        },
        written=[output / name for name in written],
        warnings=marks,
    )


def register(app: typer.Typer) -> None:
    """Add ``trajectory`` and ``report`` to the ``acscal`` app."""
    app.command(cls=AcsCommand)(trajectory)
    app.command(cls=AcsCommand)(report)
