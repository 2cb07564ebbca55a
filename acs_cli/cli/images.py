"""Commands on calibration images: ``acscal intrinsics`` and ``acscal poses``.

Thin Typer commands over :mod:`acs_cli.stages.intrinsics` and :mod:`acs_cli.stages.poses`;
:func:`register` adds them to the ``acscal`` app.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, cast

import typer

from acs_cli.cli.help_format import AcsCommand
from acs_cli.cli.output import AcceptWeakOpt, JsonOpt, artifact_result, emit, err, out, warn
from acs_cli.errors import InputError

if TYPE_CHECKING:
    from rich.progress import Progress, TaskID

    from acs_cli.core.targets import MarkerTarget
    from acs_cli.io.video import FrameSelection
    from acs_cli.stages.poses import PosesRun, SfmPosesRun

__all__ = ["intrinsics", "parse_board", "poses", "register"]

_BOARD = re.compile(r"^\s*(\d+)\s*[xX*,]\s*(\d+)\s*$")


class CameraModel(str, Enum):
    pinhole = "pinhole"
    rational = "rational"
    fisheye = "fisheye"


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` -> ``(9, 6)``: inner corners along the board's x axis and y axis.

    Raises
    ------
    InputError
        Not ``COLSxROWS`` with both at least 2 and at most
        :data:`~acs_cli.core.checkerboard.MAX_BOARD_CORNERS`.
    """
    from acs_cli.core.checkerboard import MAX_BOARD_CORNERS

    m = _BOARD.match(text)
    if not m:
        raise InputError(f"--board must be COLSxROWS inner corners, e.g. 9x6; got {text!r}")
    cols, rows = int(m.group(1)), int(m.group(2))
    if cols < 2 or rows < 2:
        raise InputError(f"--board needs at least 2x2 inner corners, got {cols}x{rows}")
    if max(cols, rows) > MAX_BOARD_CORNERS:
        raise InputError(
            f"--board {cols}x{rows}: at most {MAX_BOARD_CORNERS} inner corners along a side"
        )
    return cols, rows


class _NoBar:
    """:func:`_bar` when stderr is not a terminal: nothing drawn, and rich's progress module
    (40-60 ms of a command's start) not imported."""

    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def add_task(self, *args: Any, **kwargs: Any) -> TaskID:
        return cast("TaskID", 0)

    def update(self, *args: Any, **kwargs: Any) -> None:
        return None

    def reset(self, *args: Any, **kwargs: Any) -> None:
        return None


def _bar() -> Progress | _NoBar:
    """A transient rich bar on stderr (its task's description, the count, the time left);
    none when stderr is not a terminal: a log or a pipe then holds only the messages."""
    if not err.is_terminal:
        return _NoBar()
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
        TimeRemainingColumn(), console=err.rich, transient=True,
    )  # fmt: skip


@contextmanager
def _progress(label: str) -> Iterator[Callable[[int, int], None]]:
    """A rich progress bar on stderr; yields the ``progress(done, total)`` callback.

    Off when stderr is not a terminal: a log or a pipe then holds only the messages (a
    transient bar would still leave an empty line there).
    """
    with _bar() as bar:
        task = bar.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


BoardOpt = Annotated[
    str | None,
    typer.Option(
        "--board", help="Inner corners of the checkerboard, COLSxROWS (e.g. 9x6). (default: 9x6)"
    ),
]
SquareOpt = Annotated[
    float | None,
    typer.Option("--square", help="Side of a board square, metres. (default: 0.025)", min=0.0),
]
EveryOpt = Annotated[
    int | None,
    typer.Option(
        "--every",
        min=1,
        help="Video input: use every n-th frame (frames 0, n, 2n, ...). (default: 1)",
    ),
]
MaxFramesOpt = Annotated[
    int | None,
    typer.Option(
        "--max-frames",
        min=1,
        help="Video input: use at most this many frames, spread evenly over the recording "
        "(after --every).",
    ),
]


SkipBlurredOpt = Annotated[
    bool,
    typer.Option(
        "--skip-blurred",
        help="Video input: skip frames whose sharpness is below half the median of the last "
        "15 selected frames (motion blur; docs/formats.md, video files).",
    ),
]
MinChangeOpt = Annotated[
    float | None,
    typer.Option(
        "--min-change",
        min=0.0,
        max=1.0,
        metavar="SHARE",
        help="Video input: skip frames that differ from the last kept one by less than this "
        "share of the grey range (mean absolute difference; e.g. 0.02: a camera standing "
        "still).",
    ),
]


def frame_selection(
    every: int | None,
    max_frames: int | None,
    skip_blurred: bool = False,
    min_change: float | None = None,
) -> FrameSelection:
    """``--every``, ``--max-frames``, ``--skip-blurred`` and ``--min-change`` as a
    :class:`FrameSelection`."""
    from acs_cli.io.video import FrameSelection

    return FrameSelection(1 if every is None else every, max_frames, skip_blurred, min_change)


TopicOpt = Annotated[
    str | None,
    typer.Option(
        "--topic",
        help="ROS bag input (ROS 1 .bag, ROS 2 bag folder): the image topic "
        "(sensor_msgs/Image or CompressedImage); times are header.stamp.",
    ),
]
TargetOpt = Annotated[
    str | None,
    typer.Option(
        "--target",
        help="An AprilGrid or ChArUco target instead of the checkerboard: a target YAML "
        "(Kalibr's aprilgrid file as it is, or target_type: charuco with OpenCV's names) or "
        "a short form, aprilgrid:6x6:0.088:0.3 (tags, tag size m, spacing ratio) or "
        "charuco:11x8:0.03:0.022:DICT_5X5_100 (squares, square m, marker m, dictionary).",
    ),
]


def parse_target_option(
    target: str | None, board: str | None, square: float | None
) -> tuple[int | None, int | None, float | None, MarkerTarget | None]:
    """``--target`` and ``--board``/``--square`` (which exclude each other) as
    ``(cols, rows, square, target)``: a checkerboard (given either way) as its corners and
    square, an AprilGrid or ChArUco as ``target``; what was not given is None.

    Raises
    ------
    InputError
        ``--target`` with ``--board`` or ``--square``, or a bad target or board.
    """
    if target is None:
        cols, rows = parse_board(board) if board is not None else (None, None)
        return cols, rows, square, None
    given = [k for k, v in {"--board": board, "--square": square}.items() if v is not None]
    if given:
        raise InputError(
            f"{' and '.join(given)} {'describe' if len(given) > 1 else 'describes'} a "
            "checkerboard and --target replaces them: give one or the other"
        )
    from acs_cli.core.targets import Checkerboard
    from acs_cli.io.target import parse_target

    tgt = parse_target(target)
    if isinstance(tgt, Checkerboard):
        return tgt.cols, tgt.rows, tgt.square, None
    return None, None, None, tgt


WorkersOpt = Annotated[
    int | None,
    typer.Option("--workers", min=1, help="Detection processes (default: all CPU cores)."),
]


def intrinsics(
    images_dir: Annotated[
        Path,
        typer.Argument(
            help="Folder of checkerboard images, or a video file (.mp4, .mkv, .mov, .avi, ...)."
        ),
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="intrinsics.yaml to write.")],
    board: BoardOpt = None,
    square: SquareOpt = None,
    target: TargetOpt = None,
    model: Annotated[
        CameraModel,
        typer.Option(
            "--model",
            help="pinhole (k1 k2 p1 p2 k3), rational (8 coefficients) or fisheye (equidistant).",
        ),
    ] = CameraModel.pinhole,
    export: Annotated[
        list[str] | None,
        typer.Option(
            "--export",
            metavar="ros,opencv",
            help="Also write ros (<stem>_camera_info.yaml) and/or opencv (<stem>_opencv.yaml) "
            "beside it: a comma-separated list (ros,opencv), or repeat the option.",
        ),
    ] = None,
    camera_name: Annotated[
        str,
        typer.Option(
            "--camera-name",
            help="camera_name of the ROS camera_info (the camera driver's name; letters, "
            "digits, _).",
        ),
    ] = "camera",
    workers: WorkersOpt = None,
    every: EveryOpt = None,
    max_frames: MaxFramesOpt = None,
    skip_blurred: SkipBlurredOpt = False,
    min_change: MinChangeOpt = None,
    topic: TopicOpt = None,
    accept_weak: AcceptWeakOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Calibrate a camera's intrinsics from checkerboard (or AprilGrid, ChArUco) images.

    With --target, every identified corner counts: a view showing part of the target is
    used when it has at least 8 corners not on one line.

    Detections are cached in <output stem>.detections.npz, so a rerun (or `acscal poses`)
    reuses them and an interrupted run resumes.

    Examples:

        acscal intrinsics images/cam_a --board 9x6 --square 0.025 -o cam_a/intrinsics.yaml

        acscal intrinsics images/cam_a --target april_6x6.yaml -o cam_a/intrinsics.yaml

        acscal intrinsics images/left -o left/intrinsics.yaml --export ros,opencv --camera-name left

        acscal intrinsics board.mp4 --board 9x6 --max-frames 60 -o cam_a/intrinsics.yaml
    """
    from acs_cli.cli.options import parse_list_option
    from acs_cli.stages.intrinsics import EXPORTS, IntrinsicsConfig, run_intrinsics

    cols, rows, sq, tgt = parse_target_option(target, board, square)
    defaults = IntrinsicsConfig()
    cfg = IntrinsicsConfig(
        cols=defaults.cols if cols is None else cols,
        rows=defaults.rows if rows is None else rows,
        square=defaults.square if sq is None else sq,
        model=model.value,
        export=parse_list_option(export or [], EXPORTS, "--export"),
        camera_name=camera_name,
        workers=workers,
        target=tgt,
        accept_weak=accept_weak,
        selection=frame_selection(every, max_frames, skip_blurred, min_change),
        topic=topic,
    )
    with _progress("detecting") as progress:
        run = run_intrinsics(images_dir, output, cfg, progress)
    cal = run.calibration
    K = cal.camera_matrix
    imgs = run.artifact["images"]
    out.print(
        f"{len(imgs['used'])} of {imgs['total']} images used "
        f"({run.detections.cached} detections from the cache)"
    )
    out.print(
        f"fx {K[0, 0]:.2f}  fy {K[1, 1]:.2f}  cx {K[0, 2]:.2f}  cy {K[1, 2]:.2f} px; "
        f"distortion [{', '.join(f'{v:+.5f}' for v in cal.distortion)}]"
    )
    out.print(f"reprojection RMS {cal.rms_px:.4f} px")
    warn(run.warnings)
    written = [str(output), *map(str, run.exports.values())]
    out.print(f"wrote {', '.join(written)}")
    emit(artifact_result(run.artifact), written=written, warnings=run.warnings)


class Matching(str, Enum):
    auto = "auto"
    sequential = "sequential"
    exhaustive = "exhaustive"


@contextmanager
def _phase_progress() -> Iterator[Callable[[str, int, int], None]]:
    """Progress of a run in phases on stderr: a line as each phase starts, and a bar.

    Yields the ``progress(phase, done, total)`` callback. The bar is off when stderr is not
    a terminal; the phase lines are always printed.
    """
    with _bar() as bar:
        task = bar.add_task("", total=None)
        current = [""]

        def update(phase: str, done: int, total: int) -> None:
            if phase != current[0]:
                current[0] = phase
                err.print(f"sfm: {phase} ({total} images)")
                bar.reset(task, description=phase, total=total, completed=done)
            bar.update(task, completed=done, total=total)

        yield update


def poses(
    images_dir: Annotated[
        Path,
        typer.Argument(
            help="Folder of checkerboard images (or of any images with --sfm), or a video "
            "file (.mp4, .mkv, .mov, .avi, ...)."
        ),
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="poses.npz to write.")],
    intrinsics_file: Annotated[
        Path | None,
        typer.Option(
            "--intrinsics",
            help="intrinsics.yaml from `acscal intrinsics` (required for board poses; with "
            "--sfm optional: without it COLMAP self-calibrates the camera).",
        ),
    ] = None,
    board: Annotated[
        str | None,
        typer.Option("--board", help="Inner corners, COLSxROWS (default: the intrinsics')."),
    ] = None,
    square: Annotated[
        float | None,
        typer.Option("--square", min=0.0, help="Square side, metres (default: the intrinsics')."),
    ] = None,
    target: Annotated[
        str | None,
        typer.Option(
            "--target",
            help="An AprilGrid or ChArUco target (a target YAML or a short form, as for "
            "`acscal intrinsics`); default: the intrinsics' target, when it records one.",
        ),
    ] = None,
    tum: Annotated[
        Path | None, typer.Option("--tum", help="Also write the trajectory as a TUM file.")
    ] = None,
    workers: WorkersOpt = None,
    sfm: Annotated[
        bool,
        typer.Option(
            "--sfm",
            help="Markerless: structure from motion (pycolmap) on the image sequence, no "
            "board; poses up to an unknown scale.",
        ),
    ] = False,
    matching: Annotated[
        Matching | None,
        typer.Option(
            "--matching",
            help="--sfm: sequential (video: neighbouring frames, plus loop closure), "
            "exhaustive (every pair) or auto (exhaustive up to 40 images). (default: auto)",
        ),
    ] = None,
    loop_closure: Annotated[
        bool | None,
        typer.Option(
            "--loop-closure/--no-loop-closure",
            help="--sfm, sequential matching: also match frames that look alike (the sequence "
            "returning to a place), with a vocabulary trained on its own features. "
            "(default: on)",
        ),
    ] = None,
    vocab_tree: Annotated[
        Path | None,
        typer.Option(
            "--vocab-tree",
            help="--sfm: a COLMAP 4 vocabulary-tree file for loop closure instead of training one.",
        ),
    ] = None,
    refine_intrinsics: Annotated[
        bool,
        typer.Option(
            "--refine-intrinsics",
            help="--sfm: refine the --intrinsics' focal lengths and distortion (default: held "
            "fixed).",
        ),
    ] = False,
    max_image_size: Annotated[
        int | None,
        typer.Option(
            "--max-image-size",
            min=32,
            help="--sfm: downscale larger images to this many pixels (longer side) for "
            "feature extraction. (default: full size)",
        ),
    ] = None,
    max_features: Annotated[
        int | None,
        typer.Option(
            "--max-features",
            min=30,
            help="--sfm: most SIFT features per image (fewer is faster). (default: 8192)",
        ),
    ] = None,
    workdir: Annotated[
        Path | None,
        typer.Option(
            "--workdir",
            help="--sfm: keep COLMAP's database and models in this folder (new, empty, or "
            "from an earlier --sfm run). (default: a temporary folder)",
        ),
    ] = None,
    timestamps: Annotated[
        Path | None,
        typer.Option(
            "--timestamps",
            help="A CSV of image name and time in seconds (or nanoseconds under a '[ns]' "
            "header, as EuRoC's data.csv), instead of the times in the file names.",
        ),
    ] = None,
    fps: Annotated[
        float | None,
        typer.Option(
            "--fps",
            help="Frame rate: turns frame numbers in the file names (img_00010.png) into "
            "seconds. Without it (or --timestamps) such times stay frame numbers.",
        ),
    ] = None,
    every: EveryOpt = None,
    max_frames: MaxFramesOpt = None,
    skip_blurred: SkipBlurredOpt = False,
    min_change: MinChangeOpt = None,
    topic: TopicOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Each image's camera pose, as a trajectory: on a board, or markerless (--sfm).

    Writes an acscal/poses NPZ that `acscal joint` and `acscal relpose` read directly.
    Board poses have world = the board, in metres.

    Times come from the file names: a decimal number is seconds, an integer of 18 or more
    digits nanoseconds (ROS, EuRoC), of 9-17 digits seconds, ms or us of Unix time, and a
    shorter integer a frame number (give --fps, or --timestamps FILE). A video file's frames
    are timed by their presentation timestamps and named frame_000123 by index; --every and
    --max-frames select among them.

    With --sfm, incremental structure from motion (COLMAP) poses the registered images:
    world = the first registered camera, translations in SfM units (unknown scale: for
    `acscal relpose --unknown-scale`); --workers sets COLMAP's threads.

    Examples:

        acscal poses images/cam_a --intrinsics cam_a/intrinsics.yaml --board 9x6 \\
            --square 0.025 -o cam_a/poses.npz --tum cam_a/poses.txt

        acscal poses walk.mp4 --sfm --intrinsics cam_a/intrinsics.yaml --max-frames 200 \\
            -o cam_a/poses.npz --tum cam_a/poses.txt
    """
    if sfm:
        if target is not None:
            raise InputError(
                "--target describes a calibration target, which --sfm does not use; leave it out"
            )
        _sfm_poses(
            images_dir,
            intrinsics_file,
            output,
            tum=tum,
            workers=workers,
            board=board,
            square=square,
            matching=matching,
            loop_closure=loop_closure,
            vocab_tree=vocab_tree,
            refine_intrinsics=refine_intrinsics,
            max_image_size=max_image_size,
            max_features=max_features,
            workdir=workdir,
            timestamps=timestamps,
            fps=fps,
            selection=frame_selection(every, max_frames, skip_blurred, min_change),
            topic=topic,
        )
        return
    from acs_cli.stages.poses import PosesConfig, run_poses

    sfm_only = {
        "--matching": matching is not None,
        "--loop-closure/--no-loop-closure": loop_closure is not None,
        "--vocab-tree": vocab_tree is not None,
        "--refine-intrinsics": refine_intrinsics,
        "--max-image-size": max_image_size is not None,
        "--max-features": max_features is not None,
        "--workdir": workdir is not None,
    }
    given = [k for k, v in sfm_only.items() if v]
    if given:
        raise InputError(f"{', '.join(given)} only apply with --sfm (markerless poses)")
    if intrinsics_file is None:
        raise InputError(
            "board poses need --intrinsics (from `acscal intrinsics`); for markerless poses "
            "without a board give --sfm"
        )
    cols, rows, sq, tgt = parse_target_option(target, board, square)
    cfg = PosesConfig(
        cols=cols,
        rows=rows,
        square=sq,
        target=tgt,
        tum=tum,
        workers=workers,
        timestamps=timestamps,
        fps=fps,
        selection=frame_selection(every, max_frames, skip_blurred, min_change),
        topic=topic,
    )
    with _progress("detecting") as progress:
        run = run_poses(images_dir, intrinsics_file, output, cfg, progress)
    n = len(run.trajectory)
    rms = run.reprojection_rms
    out.print(
        f"{n} poses ({run.cached} detections from a cache); reprojection RMS median "
        f"{float(sorted(rms)[len(rms) // 2]):.4f} px, max {float(rms.max()):.4f} px"
    )
    warn(run.warnings)
    out.print(f"wrote {output}" + (f", {tum}" if tum is not None else ""))
    emit(_poses_result(run), written=[output, *([tum] if tum else [])], warnings=run.warnings)


def _poses_result(run: PosesRun | SfmPosesRun) -> dict[str, Any]:
    """``acscal poses --json``'s result, from the stage's typed result.

    The number of poses, the time unit, the reprojection RMS per posed image (pixels, with
    its median and maximum); board poses add the images skipped and the detections cached,
    markerless ones the SfM summary (registered images, points, intrinsics used).
    """
    import numpy as np

    from acs_cli.stages.poses import SfmPosesRun

    rms = np.asarray(run.reprojection_rms, dtype=float)
    traj = run.trajectory
    result: dict[str, Any] = {
        "poses": len(traj),
        "time_unit": traj.time_unit,
        "reprojection_rms_px": {
            "median": float(np.median(rms)) if rms.size else None,
            "max": float(rms.max()) if rms.size else None,
            "per_image": dict(zip(traj.names, rms.tolist(), strict=True)) if traj.names else rms,
        },
    }
    if isinstance(run, SfmPosesRun):
        res = run.result
        result["sfm"] = {
            "images": len(res.image_names),
            "registered": int(np.count_nonzero(res.registered)),
            "num_points3d": res.num_points3d,
            "mean_track_length": res.mean_track_length,
            "reprojection_rms_px": res.reprojection_rms,
            "intrinsics_source": res.intrinsics_source,
            "intrinsics_refined": res.intrinsics_refined,
            "camera_matrix": res.camera.camera_matrix,
            "matching": res.matching,
            "loop_closure": res.loop_closure,
            "metric_scale": False,
        }
    else:
        result |= {"skipped": list(run.skipped), "cached": run.cached}
    return result


def _sfm_poses(
    images_dir: Path,
    intrinsics_file: Path | None,
    output: Path,
    *,
    tum: Path | None,
    workers: int | None,
    board: str | None,
    square: float | None,
    matching: Matching | None,
    loop_closure: bool | None,
    vocab_tree: Path | None,
    refine_intrinsics: bool,
    max_image_size: int | None,
    max_features: int | None,
    workdir: Path | None,
    timestamps: Path | None,
    fps: float | None,
    selection: FrameSelection,
    topic: str | None,
) -> None:
    """``acscal poses --sfm``: the markerless front end."""
    from acs_cli.stages.poses import SfmPosesConfig, run_sfm_poses

    board_opts = [k for k, v in {"--board": board, "--square": square}.items() if v is not None]
    if board_opts:
        raise InputError(
            f"{' and '.join(board_opts)} describe a checkerboard, which --sfm does not use; "
            "leave them out"
        )
    cfg = SfmPosesConfig(
        tum=tum,
        workers=workers,
        matching=(matching or Matching.auto).value,
        loop_closure=True if loop_closure is None else loop_closure,
        vocab_tree=vocab_tree,
        refine_intrinsics=refine_intrinsics,
        max_image_size=max_image_size,
        max_features=8192 if max_features is None else max_features,
        workdir=workdir,
        timestamps=timestamps,
        fps=fps,
        selection=selection,
        topic=topic,
    )
    with _phase_progress() as progress:
        run = run_sfm_poses(images_dir, intrinsics_file, output, cfg, progress)
    res = run.result
    n_all = len(res.image_names)
    n = len(run.trajectory)
    out.print(
        f"{n} of {n_all} images registered ({100.0 * n / n_all:.0f}%); {res.num_points3d} "
        f"points, mean track length {res.mean_track_length:.2f}, reprojection RMS "
        f"{res.reprojection_rms:.3f} px"
    )
    K = res.camera.camera_matrix
    how = (
        "self-calibrated"
        if res.intrinsics_source == "self-calibrated"
        else ("given, refined" if res.intrinsics_refined else "given, held fixed")
    )
    out.print(
        f"intrinsics ({how}, {res.camera.model}): fx {K[0, 0]:.2f}  fy {K[1, 1]:.2f}  "
        f"cx {K[0, 2]:.2f}  cy {K[1, 2]:.2f} px"
    )
    total = res.seconds.get("total", 0.0)
    out.print(
        f"{res.matching} matching, loop closure: {res.loop_closure}"
        + (f" ({res.loop_pairs} loop pairs)" if res.loop_pairs else "")
        + f"; {total:.1f} s ({total / n_all:.2f} s per image)"
    )
    out.print("scale unknown: translations are in SfM units (use `acscal relpose --unknown-scale`)")
    warn(run.warnings)
    out.print(f"wrote {output}" + (f", {tum}" if tum is not None else ""))
    emit(_poses_result(run), written=[output, *([tum] if tum else [])], warnings=run.warnings)


def register(app: typer.Typer) -> None:
    """Add ``intrinsics`` and ``poses`` to the ``acscal`` app."""
    app.command(cls=AcsCommand)(intrinsics)
    app.command(cls=AcsCommand)(poses)
