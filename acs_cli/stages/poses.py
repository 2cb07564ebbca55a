"""The poses stage: ``acscal poses`` (one board pose per image, as a trajectory).

Each image with a detected board gives ``T_cam_board`` (PnP); the trajectory stores its
inverse ``T_world_cam`` with world = the board. Timestamps are the last number in each
file name when those increase strictly, else the image indices.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.core.intrinsics import board_points
from acs_cli.core.pnp import (
    board_pose,
    camera_in_board,
    consistent_corner_order,
    reversed_order_transform,
)
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header
from acs_cli.io.atomic import check_distinct_output, check_writable
from acs_cli.io.detections import cache_path_for
from acs_cli.io.images import list_images, timestamp_from_name
from acs_cli.io.intrinsics import BoardSpec, IntrinsicsArtifact
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import Trajectory, write_tum
from acs_cli.stages.intrinsics import detect_folder, no_board_error

__all__ = ["CameraIntrinsics", "PosesConfig", "PosesRun", "read_intrinsics", "run_poses"]

Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class PosesConfig:
    """Options of the poses stage.

    Attributes
    ----------
    cols, rows : int, optional
        Inner corners of the board; default: the intrinsics artifact's board.
    square : float, optional
        Square side, metres; default: the intrinsics artifact's.
    tum : Path, optional
        Also write the trajectory as a TUM file.
    workers : int, optional
        Detection processes (default ``os.cpu_count()``).
    """

    cols: int | None = None
    rows: int | None = None
    square: float | None = None
    tum: Path | None = None
    workers: int | None = None


#: Kept for callers of the former reader: the intrinsics artifact's class.
CameraIntrinsics = IntrinsicsArtifact


@dataclass(frozen=True)
class PosesRun:
    """What :func:`run_poses` did."""

    trajectory: Trajectory
    reprojection_rms: np.ndarray
    skipped: list[str]
    output: Path
    cached: int
    warnings: list[str] = field(default_factory=list)


def read_intrinsics(path: Path) -> IntrinsicsArtifact:
    """Read and check an ``acscal/intrinsics`` artifact (:meth:`IntrinsicsArtifact.load`).

    Raises
    ------
    InputError
        Not an intrinsics artifact, or a key of the wrong shape or value.
    """
    return IntrinsicsArtifact.load(path)


def _timestamps(names: list[str], all_names: list[str]) -> tuple[np.ndarray, bool]:
    """Timestamps from file names if they increase strictly, else the folder indices."""
    stamps = [timestamp_from_name(n) for n in names]
    if all(s is not None for s in stamps):
        t = np.array(stamps, dtype=float)
        if t.size < 2 or np.all(np.diff(t) > 0):
            return t, True
    index = {n: i for i, n in enumerate(all_names)}
    return np.array([index[n] for n in names], dtype=float), False


def _board_option(value: Any, stored: Any, name: str, path: Path) -> Any:
    if value is not None:
        return value
    if stored is None:
        raise InputError(
            f"the intrinsics artifact records no board {name}: give --board/--square", path=path
        )
    return stored


def run_poses(
    images_dir: Path,
    intrinsics: Path,
    output: Path,
    config: PosesConfig,
    progress: Progress | None = None,
) -> PosesRun:
    """Detect the board, solve each image's pose and write the ``acscal/poses`` NPZ.

    Raises
    ------
    InputError
        Bad options or files, no board in any image, images of another size than the
        intrinsics'.
    """
    cam = read_intrinsics(intrinsics)
    board = cam.board or BoardSpec()
    cols = int(_board_option(config.cols, board.cols, "size", intrinsics))
    rows = int(_board_option(config.rows, board.rows, "size", intrinsics))
    square = float(_board_option(config.square, board.square, "square", intrinsics))
    if cols < 2 or rows < 2:
        raise InputError(f"--board needs at least 2x2 inner corners, got {cols}x{rows}")
    if not (np.isfinite(square) and square > 0):
        raise InputError(f"--square must be a positive length in metres, got {square}")
    outputs = [output] + ([config.tum] if config.tum is not None else [])
    inputs = [images_dir, intrinsics, *list_images(images_dir)]
    for o in outputs:
        check_distinct_output(o, inputs)
    if config.tum is not None and Path(config.tum).resolve() == output.resolve():
        raise InputError("--tum and -o name the same file", path=output)
    for o in [*outputs, cache_path_for(output)]:
        check_writable(o)  # before the detection, and before the first output is replaced

    fd = detect_folder(
        images_dir,
        cols,
        rows,
        cache_path_for(output),
        extra_caches=[cache_path_for(intrinsics)],
        workers=config.workers,
        progress=progress,
    )
    if fd.image_size != cam.image_size:
        raise InputError(
            f"images are {fd.image_size[0]}x{fd.image_size[1]} but {intrinsics.name} was "
            f"calibrated at {cam.image_size[0]}x{cam.image_size[1]}",
            path=images_dir,
        )
    obj = board_points(cols, rows, square)
    all_names = [p.name for p in fd.images]
    names: list[str] = []
    T_cb: list[np.ndarray] = []
    rms: list[float] = []
    corners: list[np.ndarray] = []
    skipped: list[str] = []
    for p, d in zip(fd.images, fd.detections, strict=True):
        pose = None
        if d.found and d.corners is not None:
            pose = board_pose(obj, d.corners, cam.camera_matrix, cam.distortion, cam.model)
        if pose is None or d.corners is None:
            skipped.append(p.name)
            continue
        names.append(p.name)
        T_cb.append(pose.T_cam_board)
        rms.append(pose.rms_px)
        corners.append(np.asarray(d.corners, dtype=float).reshape(-1, 2))
    if not names:
        raise no_board_error(images_dir, cols, rows, len(fd.images))
    t, has_t = _timestamps(names, all_names)
    warnings: list[str] = []
    # one board frame for the whole sequence: undo 180-degree relabellings of the board
    T_cb_arr = np.stack(T_cb)
    if cols != rows:
        order = np.argsort(t, kind="stable")
        flip = np.zeros(len(names), dtype=bool)
        flip[order] = consistent_corner_order(T_cb_arr[order, :3, :3])
        if flip.any():
            T_cb_arr[flip] = T_cb_arr[flip] @ reversed_order_transform(cols, rows, square)
            for i in np.flatnonzero(flip):
                corners[i] = corners[i][::-1].copy()
            warnings.append(
                f"{int(flip.sum())} image(s) had the board's corners in the other of its two "
                "orders (the camera rolled past 90 degrees); relabelled so the board's frame "
                "is one for the whole sequence"
            )
    T_wc = camera_in_board(T_cb_arr)
    traj = Trajectory(
        t, T_wc, source=str(output), format="npz", has_timestamps=has_t, names=tuple(names)
    )
    if skipped:
        warnings.append(f"no board pose in {len(skipped)} image(s): {', '.join(skipped[:10])}")
    header = make_header(
        "poses",
        {"images": images_dir, "intrinsics": intrinsics},
        method="cv2.solvePnP (SOLVEPNP_IPPE) refined by cv2.solvePnPRefineLM on "
        f"{cols}x{rows} board corners; T_world_cam = inverse of T_cam_board",
        units={"length": "m", "reprojection_rms": "px", "timestamps": "s or frame number"},
        frames={
            "world": "the board (origin at its first inner corner, z into the board)",
            "cam": "the camera's optical frame",
        },
    )
    header["board"] = {"cols": cols, "rows": rows, "square": square, "units": "m"}
    header["intrinsics_file"] = str(intrinsics)
    header["timestamps_from"] = "file names" if has_t else "image indices"
    rms_arr = np.array(rms, dtype=float)
    PosesArtifact(
        trajectory=traj,
        reprojection_rms=rms_arr,
        skipped_images=tuple(skipped),
        # the observations themselves, for a bundle adjustment downstream
        corners=np.stack(corners),
        board_points=np.asarray(obj, dtype=float).reshape(-1, 3),
        header=header,
    ).save(output)
    if config.tum is not None:
        write_tum(config.tum, t, T_wc)
    return PosesRun(traj, rms_arr, skipped, output, fd.cached, warnings)
