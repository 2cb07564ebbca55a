"""The ``acscal`` command line: thin Typer commands over the stages.

Errors the user can cause (:class:`acs_cli.errors.AcsError`) become one line on stderr and
an exit code: 2 for bad input, 3 for motion that cannot determine the answer. Anything
else is a bug and keeps its traceback. A library warning that escapes (NumPy's, SciPy's: a
bug too, each is fixed where it arises) is one line of acscal's, never Python's two.
"""

from __future__ import annotations

import gc
import sys
import warnings
from enum import Enum
from pathlib import Path
from types import FrameType
from typing import Annotated, Any

import typer

import acs_cli
from acs_cli.cli.help_format import AcsCommand, AcsGroup
from acs_cli.cli.output import (
    AcceptWeakOpt,
    JsonOpt,
    artifact_result,
    emit,
    emit_error,
    err,
    out,
    reset,
    warn,
)
from acs_cli.cli.report import FormatAOpt, FormatBOpt, PairBy, TrajFormat, positive_seconds
from acs_cli.errors import AcsError, DegenerateMotionError, InputError

# Imports here are light (typer, rich's console): numpy, the stages and what they import
# load inside the commands, so `acscal --help` and `acscal --version` start fast
# (benchmarks/bench_startup.py; tests/unit/test_lazy_imports.py guards it).
app = typer.Typer(
    name="acscal",
    cls=AcsGroup,
    help="Calibrate articulated camera systems: joints, relative poses and scale factors "
    "(Chen & Wong's Algorithms I-IV, and beyond).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


BundleOpt = Annotated[
    bool,
    typer.Option(
        "--bundle/--no-bundle",
        help="Refined method, poses NPZs from `acscal poses`: refine the result, the joint "
        "and the intrinsics by bundle adjustment on the detected corners (the "
        "maximum-likelihood fit on the pixels). Trajectories without corners are used as "
        "they are.",
    ),
]


class Method(str, Enum):
    refined = "refined"
    paper = "paper"


class JointType(str, Enum):
    ball = "ball"
    hinge = "hinge"
    rigid = "rigid"


def _joint_type_opt(help_text: str) -> Any:
    return typer.Option("--joint-type", help=help_text)


class ExportFormat(str, Enum):
    kalibr = "kalibr"
    opencv = "opencv"
    ros = "ros"
    urdf = "urdf"
    handeye = "handeye"


MethodOpt = Annotated[
    Method,
    typer.Option(
        "--method",
        help="refined (default: all constraints, noise-weighted, robust) or paper (as published).",
    ),
]
PairByOpt = Annotated[
    PairBy, typer.Option("--pair-by", help="Pair A's and B's samples by timestamp or index.")
]
MaxDtOpt = Annotated[
    float | None,
    typer.Option(
        "--max-dt",
        help="Largest timestamp difference of a pair, seconds (default: half the median "
        "frame interval).",
        callback=positive_seconds,
    ),
]
UnitOpt = Annotated[
    str, typer.Option("--length-unit", help="Unit of the trajectories' translations (label).")
]


def _fmt(v: Any, digits: int = 4) -> str:
    import numpy as np

    arr = np.atleast_1d(np.asarray(v, dtype=float))
    return "[" + ", ".join(f"{x:+.{digits}f}" for x in arr) + "]"


def _version_callback(value: bool) -> None:
    if value:
        out.print(f"acscal {acs_cli.__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version_callback, is_eager=True, help="Show the version."
        ),
    ] = False,
) -> None:
    """Calibrate articulated camera systems."""


@app.command(cls=AcsCommand)
def joint(
    poses_a: Annotated[
        Path, typer.Option("--poses-a", help="Camera A's trajectory (TUM, KITTI, COLMAP, NPZ).")
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="joint.yaml to write.")],
    poses_b: Annotated[
        Path | None, typer.Option("--poses-b", help="Camera B's trajectory.")
    ] = None,
    fixed_joint: Annotated[
        bool,
        typer.Option("--fixed-joint", help="Algorithm II: the joint stayed fixed in the world."),
    ] = False,
    overlap: Annotated[
        bool,
        typer.Option(
            "--overlap", help="Algorithm I: both trajectories in one world (shared view)."
        ),
    ] = False,
    method: MethodOpt = Method.refined,
    bundle: BundleOpt = True,
    format_a: FormatAOpt = TrajFormat.auto,
    format_b: FormatBOpt = TrajFormat.auto,
    pair_by: PairByOpt = PairBy.auto,
    max_dt: MaxDtOpt = None,
    length_unit: UnitOpt = "m",
    accept_weak: AcceptWeakOpt = False,
    joint_type: Annotated[
        JointType,
        _joint_type_opt(
            "--overlap, refined method: the joint is a ball (default) or a hinge (its axis "
            "in each camera is written too); rigid is refused (no joint point: use relpose)."
        ),
    ] = JointType.ball,
    json_out: JsonOpt = False,
) -> None:
    """Locate the joint in each camera's frame.

    Example (fixed-joint motion, each camera on its own checkerboard):

        acscal joint --fixed-joint --poses-a cam_a.tum --poses-b cam_b.tum -o joint.yaml

    Example (overlapping views of one board):

        acscal joint --overlap --poses-a cam_a.tum --poses-b cam_b.tum -o joint.yaml
    """
    from rich.table import Table

    from acs_cli.stages.joint import JointConfig, run_joint

    if fixed_joint == overlap:
        raise InputError("choose one of --fixed-joint and --overlap")
    cfg = JointConfig(
        scenario="overlap" if overlap else "fixed_joint",
        method=method.value,
        format_a=format_a.value,
        format_b=format_b.value,
        pair_by=pair_by.value,
        max_dt=max_dt,
        length_unit=length_unit,
        bundle=bundle,
        accept_weak=accept_weak,
        joint_type=joint_type.value,
    )
    run = run_joint(poses_a, poses_b, output, cfg)
    est = run.estimate
    table = Table(title=f"joint ({cfg.scenario}, {cfg.method})", title_justify="left")
    table.add_column("quantity")
    table.add_column(f"value ({length_unit})")
    table.add_column("std")
    table.add_row("position_in_a", _fmt(est.position_in_a), _fmt(est.std_a))
    if est.position_in_b is not None and est.std_b is not None:
        table.add_row("position_in_b", _fmt(est.position_in_b), _fmt(est.std_b))
    for cam, axis in est.axis_in.items():
        std = est.axis_std_deg_in.get(cam)
        table.add_row(f"axis_in_{cam} (std deg)", _fmt(axis), "" if std is None else f"{std:.3g}")
    for key, rms in est.residual_rms.items():
        table.add_row(f"residual RMS ({key})", f"{rms:.4g}", "")
    out.print(table)
    warn(run.warnings)
    out.print(f"wrote {output}")
    emit(artifact_result(run.artifact), written=[output], warnings=run.warnings)


@app.command(cls=AcsCommand)
def relpose(
    poses_a: Annotated[Path, typer.Option("--poses-a", help="Camera A's trajectory.")],
    poses_b: Annotated[Path, typer.Option("--poses-b", help="Camera B's trajectory.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="relpose.yaml to write.")],
    joint_file: Annotated[
        Path | None,
        typer.Option(
            "--joint", help="joint.yaml from `acscal joint` (in the trajectories' units)."
        ),
    ] = None,
    joint_metric: Annotated[
        Path | None,
        typer.Option(
            "--joint-metric",
            help="A metric joint.yaml, with --unknown-scale: also estimates mu_a and mu_b.",
        ),
    ] = None,
    unknown_scale: Annotated[
        bool,
        typer.Option(
            "--unknown-scale",
            help="Algorithm IV: each trajectory is known only up to its own scale factor.",
        ),
    ] = False,
    self_calibrate: Annotated[
        bool,
        typer.Option(
            "--self-calibrate",
            help="Estimate the joint too, from this general-motion recording alone.",
        ),
    ] = False,
    reference: Annotated[
        int,
        typer.Option(
            "--reference",
            min=0,
            help="Index (from 0) of the paired frame at which T_b_a is reported.",
        ),
    ] = 0,
    method: MethodOpt = Method.refined,
    bundle: BundleOpt = True,
    format_a: FormatAOpt = TrajFormat.auto,
    format_b: FormatBOpt = TrajFormat.auto,
    pair_by: PairByOpt = PairBy.auto,
    max_dt: MaxDtOpt = None,
    length_unit: UnitOpt = "m",
    estimate_time_offset: Annotated[
        bool,
        typer.Option(
            "--estimate-time-offset",
            help="Also estimate a constant offset between the cameras' clocks (B's minus "
            "A's, time_offset_s); B's poses are interpolated on SE(3). Needs timestamps.",
        ),
    ] = False,
    max_offset: Annotated[
        float,
        typer.Option("--max-offset", min=0.0, help="Largest clock offset searched, seconds."),
    ] = 0.5,
    accept_weak: AcceptWeakOpt = False,
    joint_type: Annotated[
        JointType,
        _joint_type_opt(
            "Refined method: the joint is a ball (default), a hinge (its axis in each camera "
            "is written too) or rigid (a constant T_b_a; no joint point, no --joint)."
        ),
    ] = JointType.ball,
    json_out: JsonOpt = False,
) -> None:
    """Relative pose T_b_a of two cameras joined by a joint (no overlap needed).

    Example (Algorithm III):

        acscal relpose --joint joint.yaml --poses-a a.tum --poses-b b.tum -o relpose.yaml

    Example (Algorithm IV, monocular SLAM trajectories of unknown scale):

        acscal relpose --unknown-scale --joint joint.yaml --poses-a a.tum --poses-b b.tum \\
            -o relpose.yaml

    Example (self-calibration from one recording):

        acscal relpose --self-calibrate --poses-a a.tum --poses-b b.tum -o relpose.yaml

    Example (cameras on separate clocks):

        acscal relpose --self-calibrate --estimate-time-offset --max-offset 0.2 \\
            --poses-a a.tum --poses-b b.tum -o relpose.yaml
    """
    from rich.table import Table

    from acs_cli.stages.relpose import RelposeConfig, run_relpose

    if joint_file is not None and joint_metric is not None:
        raise InputError("give one of --joint and --joint-metric")
    cfg = RelposeConfig(
        method=method.value,
        unknown_scale=unknown_scale,
        self_calibrate=self_calibrate,
        joint_metric=joint_metric is not None,
        reference=reference,
        format_a=format_a.value,
        format_b=format_b.value,
        pair_by=pair_by.value,
        max_dt=max_dt,
        length_unit=length_unit,
        bundle=bundle,
        estimate_time_offset=estimate_time_offset,
        max_offset=max_offset,
        accept_weak=accept_weak,
        joint_type=joint_type.value,
    )
    run = run_relpose(poses_a, poses_b, joint_file or joint_metric, output, cfg)
    est = run.estimate
    rel = run.artifact["relative_pose"]
    table = Table(
        title=f"relative pose at frame {est.reference} ({cfg.method})", title_justify="left"
    )
    table.add_column("quantity")
    table.add_column("value")
    table.add_column("std")
    table.add_row(
        "roll, pitch, yaw of R_a_b (deg)", _fmt(rel["rpy_deg"], 3), _fmt(rel["rpy_deg_std"], 3)
    )
    unit = "B units" if unknown_scale else length_unit
    table.add_row(
        f"translation of B in A ({unit})",
        _fmt(rel["translation_b_in_a"]),
        _fmt(rel["translation_b_in_a_std"]),
    )
    j = run.artifact.get("joint")
    if j is not None:
        for key in ("position_in_a", "position_in_b"):
            table.add_row(f"joint.{key}", _fmt(j[key]), _fmt(j[f"{key}_std"]))
        for key in ("axis_in_a", "axis_in_b"):
            if key in j:
                table.add_row(f"joint.{key} (std deg)", _fmt(j[key]), f"{j[f'{key}_std_deg']:.3g}")
    if unknown_scale:
        table.add_row("phi_ba = mu_b / mu_a", f"{est.phi_ba:.5f}", f"{est.phi_std:.5f}")
        if est.mu_a is not None:
            table.add_row("mu_a", f"{est.mu_a:.5f}", f"{est.mu_a_std:.5f}")
            table.add_row("mu_b", f"{est.mu_b:.5f}", f"{est.mu_b_std:.5f}")
    offset = run.artifact.get("time_offset")
    if offset is not None:
        std = offset["time_offset_s_std"]
        table.add_row(
            "time_offset_s (B's clock - A's)",
            f"{offset['time_offset_s']:+.5f}",
            "inf" if std is None else f"{std:.5f}",
        )
    table.add_row("residual RMS", f"{est.residual_rms:.4g}", "")
    out.print(table)
    warn(run.warnings)
    out.print(f"wrote {output}")
    emit(artifact_result(run.artifact), written=[output], warnings=run.warnings)


@app.command(cls=AcsCommand)
def export(
    relpose_file: Annotated[
        Path, typer.Argument(help="relpose.yaml from `acscal relpose`, or a rig's rig.yaml.")
    ],
    output: Annotated[
        Path, typer.Option("-o", "--output", help="File to write (--format ros: a folder).")
    ],
    fmt: Annotated[
        ExportFormat,
        typer.Option(
            "--format",
            help="kalibr (camchain YAML with every camera's intrinsics), opencv "
            "(cv2.FileStorage YAML: R, T of T_b_a and each camera's intrinsics; relpose only), "
            "ros (a camera_info YAML per camera, in the folder -o), urdf (a rig, for "
            "robot_state_publisher) or handeye (a rig's camera on a robot's flange: "
            "easy_handeye's YAML with static_transform_publisher lines).",
        ),
    ] = ExportFormat.kalibr,
    intrinsics: Annotated[
        list[str] | None,
        typer.Option(
            "--intrinsics",
            metavar="CAMERA=FILE",
            help="A camera's intrinsics as CAMERA=intrinsics.yaml (repeat per camera; a, b "
            "for a relpose). Default: the bundle-adjusted ones the file records, else "
            "cam_CAMERA/intrinsics.yaml beside it.",
        ),
    ] = None,
    camera_name: Annotated[
        list[str] | None,
        typer.Option(
            "--camera-name",
            metavar="CAMERA=NAME",
            help="A camera's name as CAMERA=NAME (repeat per camera): ROS camera_name and "
            "file, Kalibr topic /NAME/image_raw. Default cam_a, cam_b (a rig: its names).",
        ),
    ] = None,
    scale: Annotated[
        float | None,
        typer.Option(
            "--scale",
            help="Metres per unit of the file's lengths (unknown scale: per unit of camera "
            "B's trajectory). Needed when they are not metric and have no metric joint.",
        ),
    ] = None,
    robot_name: Annotated[
        str, typer.Option("--robot-name", help="urdf: the robot's name; handeye: its namespace.")
    ] = "acs_rig",
    base_frame: Annotated[
        str, typer.Option("--base-frame", help="handeye: the robot's base tf frame.")
    ] = "base_link",
    board_frame: Annotated[
        str, typer.Option("--board-frame", help="handeye: the board's tf frame.")
    ] = "board",
    limit_margin: Annotated[
        float,
        typer.Option(
            "--limit-margin",
            metavar="DEG",
            min=0.0,
            help="urdf: degrees added on either side of each hinge's angle range over the "
            "calibration (rig.yaml's angle_range_deg) for its joint limits.",
        ),
    ] = 10.0,  # acs_cli.io.rig_export.DEFAULT_LIMIT_MARGIN_DEG (not imported at start-up)
    json_out: JsonOpt = False,
) -> None:
    """Export a relative pose, or a whole rig, for other tools.

    Example:

        acscal export run/relpose.yaml --format kalibr -o camchain.yaml

        acscal export relpose.yaml --format ros --camera-name a=left --camera-name b=right -o ros/

        acscal export relpose.yaml --format opencv --intrinsics a=a.yaml -o relpose_cv.yaml

        acscal export out/rig.yaml --format urdf -o rig.urdf

        acscal export out/rig.yaml --format handeye --camera-name flange=tool0 \\
            --camera-name cam=camera_color_optical_frame -o handeye.yaml
    """
    from acs_cli.cli.options import parse_named_option
    from acs_cli.stages.export import run_export

    given = parse_named_option(intrinsics or [], "--intrinsics", "intrinsics.yaml")
    info = run_export(
        relpose_file,
        output,
        fmt.value,
        intrinsics={c: Path(p) for c, p in given.items()},
        camera_names=parse_named_option(camera_name or [], "--camera-name", "NAME"),
        scale=scale,
        robot_name=robot_name,
        base_frame=base_frame,
        board_frame=board_frame,
        limit_margin_deg=limit_margin,
    )
    for line in info.get("static_transform_publisher", {}).get("ros1", []):
        out.print(line)
    for cam, source in info["intrinsics"].items():
        out.print(f"intrinsics of {cam}: {source}")
    warn(f"{w} (marked in the export)" for w in info["warnings"])
    for path in info["written"]:
        out.print(f"wrote {path} ({info['format']})")
    emit(info, written=info["written"], warnings=info["warnings"])


@app.command(cls=AcsCommand)
def simulate(
    output: Annotated[Path, typer.Option("-o", "--output", help="Folder for CSV and figures.")],
    trials: Annotated[int, typer.Option("--trials", min=1, help="Trials per noise level.")] = 100,
    levels: Annotated[
        int, typer.Option("--levels", min=2, help="Noise levels from 0 to the maximum.")
    ] = 9,
    frames: Annotated[int, typer.Option("--frames", min=5, help="Transformations a trial.")] = 30,
    max_rot_deg: Annotated[
        float,
        typer.Option("--max-rot-deg", min=0.0, max=180.0, help="Largest rotation noise, deg."),
    ] = 2.4,
    max_trans: Annotated[
        float,
        typer.Option("--max-trans", min=0.0, max=1000.0, help="Largest translation noise, m."),
    ] = 0.1,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the study.")] = 0,
    json_out: JsonOpt = False,
) -> None:
    """Reproduce the paper's simulation study (section 5): the paper's method beside ours.

    Writes trials.csv, summary.csv, study.yaml and the paper's figures as PNG.

    Example:

        acscal simulate -o study/ --trials 100 --levels 9
    """
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    from acs_cli.stages.simulate import SimulationConfig, run_simulate

    cfg = SimulationConfig(
        trials=trials,
        frames=frames,
        levels=levels,
        max_rot_deg=max_rot_deg,
        max_trans=max_trans,
        seed=seed,
    )
    with Progress(
        TextColumn("simulating"), BarColumn(), TextColumn("{task.completed}/{task.total}"),
        TimeRemainingColumn(), console=err.rich, transient=True, disable=not err.is_terminal,
    ) as bar:  # fmt: skip
        task = bar.add_task("trials", total=trials * levels)

        def progress(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        info = run_simulate(output, cfg, progress)
    out.print(
        f"wrote {info['trials_csv']}, {info['summary_csv']} and {len(info['figures'])} figures"
    )
    out.print(f"{info['n_rows']} rows in {info['elapsed_s']:.1f} s")
    written = [info["trials_csv"], info["summary_csv"], info["study_yaml"], *info["figures"]]
    emit(info, written=written)


from acs_cli.cli.images import register as _register_images  # noqa: E402

_register_images(app)

from acs_cli.cli.run import register as _register_run  # noqa: E402

_register_run(app)

from acs_cli.cli.report import register as _register_report  # noqa: E402

_register_report(app)


#: Exit status of a command stopped by Ctrl-C (128 + SIGINT, as shells report it).
INTERRUPTED = 130


def _show_warning(
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: object = None,
    line: str | None = None,
) -> None:
    """A warning the filters let through, as ``acscal: warning: numerical trouble in
    FUNCTION (FILE:LINE): MESSAGE``: FUNCTION is acscal's innermost, FILE:LINE the
    warning's (often in NumPy or SciPy)."""
    frame: FrameType | None = sys._getframe(1)
    where = "acscal"
    while frame is not None:
        module = str(frame.f_globals.get("__name__", ""))
        if module.startswith("acs_cli."):
            where = f"{module}.{frame.f_code.co_name}"
            break
        frame = frame.f_back
    kind = "numerical trouble" if issubclass(category, RuntimeWarning) else category.__name__
    source = "/".join(Path(filename).parts[-3:])
    err.print(
        f"acscal: warning: {kind} in {where} ({source}:{lineno}): {message}",
        markup=False,
        soft_wrap=True,
    )


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``acscal`` console script (``argv`` None: ``sys.argv``, and the
    process ends after it).

    As the console script, the objects the command leaves are frozen out of the garbage
    collector when it ends (:func:`gc.freeze`): the interpreter's exit then skips its
    collections over them, 0.08-0.1 s of every command with numpy and OpenCV loaded.
    Everything else of the exit still runs (buffers flushed, ``atexit`` handlers).
    """
    args = sys.argv[1:] if argv is None else argv
    if not args:  # a bare `acscal`: the help (the command list), as git and kubectl do
        args = ["--help"]
    reset()
    try:
        # only how a warning is shown changes, not which are: `-W error` and pytest's
        # filterwarnings still raise them
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            _main(args)
    finally:
        if argv is None:  # the process ends here (a caller's own argv: it goes on)
            gc.freeze()


def _main(args: list[str]) -> None:
    try:
        # not standalone, Typer turns Ctrl-C into a returned 130 (and typer.Exit into its
        # code): returned, not raised, so it must become the exit status here
        code = app(args=args, prog_name="acscal", standalone_mode=False)
    except AcsError as exc:
        err.print(f"acscal: error: {exc.one_line()}", markup=False, soft_wrap=True)
        details = exc.details if isinstance(exc, DegenerateMotionError) else None
        emit_error(exc.exit_code, type(exc).__name__, exc.one_line(), details)
        raise SystemExit(exc.exit_code) from None
    except typer.Abort:
        err.print("acscal: aborted")
        raise SystemExit(130) from None
    except typer.TyperException as exc:  # usage errors from the option parser: one line
        ctx = getattr(exc, "ctx", None)
        where = getattr(ctx, "command_path", None) or "acscal"
        message = f"{exc.format_message()} (see '{where} --help')"
        err.print(f"acscal: error: {message}", markup=False, soft_wrap=True)
        emit_error(exc.exit_code, "UsageError", message)
        raise SystemExit(exc.exit_code) from None
    except OSError as exc:
        where = f"{exc.filename}: " if getattr(exc, "filename", None) else ""
        message = f"{where}{exc.strerror or exc}"
        err.print(f"acscal: error: {message}", markup=False, soft_wrap=True)
        emit_error(2, "OSError", message)
        raise SystemExit(2) from None
    if code == INTERRUPTED:
        message = "interrupted (no output is left half-written: each is whole or not written)"
        err.print(f"acscal: {message}", markup=False, soft_wrap=True)
        emit_error(INTERRUPTED, "Interrupted", message)
        raise SystemExit(INTERRUPTED)
    if isinstance(code, int) and not isinstance(code, bool) and code:
        raise SystemExit(code)


if __name__ == "__main__":  # pragma: no cover
    main()
