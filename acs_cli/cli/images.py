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
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from acs_cli.errors import InputError

__all__ = ["intrinsics", "parse_board", "poses", "register"]

out = Console(highlight=False)
err = Console(stderr=True, highlight=False)

_BOARD = re.compile(r"^\s*(\d+)\s*[xX*,]\s*(\d+)\s*$")


class CameraModel(str, Enum):
    pinhole = "pinhole"
    rational = "rational"
    fisheye = "fisheye"


class Export(str, Enum):
    ros = "ros"
    opencv = "opencv"


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` -> ``(9, 6)``: inner corners along the board's x axis and y axis.

    Raises
    ------
    InputError
        Not ``COLSxROWS`` with both at least 2.
    """
    m = _BOARD.match(text)
    if not m:
        raise InputError(f"--board must be COLSxROWS inner corners, e.g. 9x6; got {text!r}")
    cols, rows = int(m.group(1)), int(m.group(2))
    if cols < 2 or rows < 2:
        raise InputError(f"--board needs at least 2x2 inner corners, got {cols}x{rows}")
    return cols, rows


@contextmanager
def _progress(label: str) -> Iterator[Callable[[int, int], None]]:
    """A rich progress bar on stderr; yields the ``progress(done, total)`` callback.

    Off when stderr is not a terminal: a log or a pipe then holds only the messages (a
    transient bar would still leave an empty line there).
    """
    with Progress(
        TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
        console=err, transient=True, disable=not err.is_terminal,
    ) as bar:  # fmt: skip
        task = bar.add_task(label, total=None)

        def update(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        yield update


BoardOpt = Annotated[
    str, typer.Option("--board", help="Inner corners of the checkerboard, COLSxROWS (e.g. 9x6).")
]
SquareOpt = Annotated[
    float, typer.Option("--square", help="Side of a board square, metres.", min=0.0)
]
WorkersOpt = Annotated[
    int | None,
    typer.Option("--workers", min=1, help="Detection processes (default: all CPU cores)."),
]


def intrinsics(
    images_dir: Annotated[Path, typer.Argument(help="Folder of checkerboard images.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="intrinsics.yaml to write.")],
    board: BoardOpt = "9x6",
    square: SquareOpt = 0.025,
    model: Annotated[
        CameraModel,
        typer.Option(
            "--model",
            help="pinhole (k1 k2 p1 p2 k3), rational (8 coefficients) or fisheye (equidistant).",
        ),
    ] = CameraModel.pinhole,
    export: Annotated[
        list[Export] | None,
        typer.Option("--export", help="Also write a ROS camera_info or OpenCV YAML beside it."),
    ] = None,
    workers: WorkersOpt = None,
) -> None:
    """Calibrate a camera's intrinsics from checkerboard images.

    Detections are cached in <output stem>.detections.npz, so a rerun (or `acscal poses`)
    reuses them and an interrupted run resumes.

    Example:

        acscal intrinsics images/cam_a --board 9x6 --square 0.025 -o cam_a/intrinsics.yaml
    """
    from acs_cli.stages.intrinsics import IntrinsicsConfig, run_intrinsics

    cols, rows = parse_board(board)
    cfg = IntrinsicsConfig(
        cols=cols,
        rows=rows,
        square=square,
        model=model.value,
        export=tuple(dict.fromkeys(e.value for e in (export or []))),
        workers=workers,
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
    for w in run.warnings:
        err.print(f"[yellow]warning:[/] {w}")
    written = [str(output), *map(str, run.exports.values())]
    out.print(f"wrote {', '.join(written)}")


def poses(
    images_dir: Annotated[Path, typer.Argument(help="Folder of checkerboard images.")],
    intrinsics_file: Annotated[
        Path, typer.Option("--intrinsics", help="intrinsics.yaml from `acscal intrinsics`.")
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="poses.npz to write.")],
    board: Annotated[
        str | None,
        typer.Option("--board", help="Inner corners, COLSxROWS (default: the intrinsics')."),
    ] = None,
    square: Annotated[
        float | None,
        typer.Option("--square", min=0.0, help="Square side, metres (default: the intrinsics')."),
    ] = None,
    tum: Annotated[
        Path | None, typer.Option("--tum", help="Also write the trajectory as a TUM file.")
    ] = None,
    workers: WorkersOpt = None,
) -> None:
    """Each image's camera pose on the board (world = board), as a trajectory.

    Writes an acscal/poses NPZ that `acscal joint` and `acscal relpose` read directly.

    Example:

        acscal poses images/cam_a --intrinsics cam_a/intrinsics.yaml --board 9x6 \\
            --square 0.025 -o cam_a/poses.npz --tum cam_a/poses.txt
    """
    from acs_cli.stages.poses import PosesConfig, run_poses

    cols, rows = parse_board(board) if board is not None else (None, None)
    cfg = PosesConfig(cols=cols, rows=rows, square=square, tum=tum, workers=workers)
    with _progress("detecting") as progress:
        run = run_poses(images_dir, intrinsics_file, output, cfg, progress)
    n = len(run.trajectory)
    rms = run.reprojection_rms
    out.print(
        f"{n} poses ({run.cached} detections from a cache); reprojection RMS median "
        f"{float(sorted(rms)[len(rms) // 2]):.4f} px, max {float(rms.max()):.4f} px"
    )
    for w in run.warnings:
        err.print(f"[yellow]warning:[/] {w}")
    out.print(f"wrote {output}" + (f", {tum}" if tum is not None else ""))


def register(app: typer.Typer) -> None:
    """Add ``intrinsics`` and ``poses`` to the ``acscal`` app."""
    app.command()(intrinsics)
    app.command()(poses)
