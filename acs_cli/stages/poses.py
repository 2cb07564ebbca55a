"""The poses stage: ``acscal poses`` (one pose per image, as a trajectory).

Board poses (:func:`run_poses`): each image with a detected board gives ``T_cam_board``
(PnP); the trajectory stores its inverse ``T_world_cam`` with world = the board.

Markerless poses (:func:`run_sfm_poses`, ``acscal poses --sfm``): incremental structure
from motion on the image sequence (:mod:`acs_cli.core.sfm`, pycolmap); the registered
images' ``T_world_cam`` with world = the first registered camera, known up to scale.

Timestamps are the last number in each file name when those increase strictly, else the
image indices.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np

from acs_cli.core.intrinsics import board_points
from acs_cli.core.pnp import (
    board_pose,
    camera_in_board,
    consistent_corner_order,
    reversed_order_transform,
)
from acs_cli.core.sfm import SfmCamera, SfmOptions, SfmProgress, SfmResult
from acs_cli.core.targets import MIN_POSE_CORNERS, Checkerboard, MarkerTarget, pose_ready
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header
from acs_cli.io.atomic import atomic_write_bytes, check_distinct_output, check_writable
from acs_cli.io.bag import is_bag_path, read_bag_frames
from acs_cli.io.detections import cache_path_for
from acs_cli.io.images import list_images, read_gray
from acs_cli.io.intrinsics import BoardSpec, IntrinsicsArtifact
from acs_cli.io.poses import PosesArtifact, SfmSummary
from acs_cli.io.target import target_from_mapping, target_to_mapping
from acs_cli.io.timestamps import (
    VIDEO_TIMES,
    ImageTimes,
    image_times,
    read_timestamps_file,
    times_from_ns,
)
from acs_cli.io.trajectory import FRAME_NUMBERS_NOTE, Trajectory, write_tum
from acs_cli.io.video import FrameSelection, VideoRead, is_video_path, read_video_frames
from acs_cli.stages.intrinsics import (
    TARGET_FRAMES,
    _input_role,
    detect_folder,
    few_boards,
    input_files,
    no_board_error,
    no_target_error,
)

__all__ = [
    "PosesConfig",
    "PosesRun",
    "SfmPosesConfig",
    "SfmPosesRun",
    "run_poses",
    "run_sfm_poses",
]

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
    timestamps : Path, optional
        A CSV of image name and time (:func:`acs_cli.io.timestamps.read_timestamps_file`).
    fps : float, optional
        Frame rate: frame numbers in the names (or the folder order) become seconds.
    target : AprilGrid or Charuco, optional
        Pose on this target (identified corners, partial views) instead of a checkerboard;
        default: the intrinsics artifact's target when it records one (and no board option
        is given).
    selection : FrameSelection
        A video's frames to use (``--every``, ``--max-frames``).
    """

    cols: int | None = None
    rows: int | None = None
    square: float | None = None
    tum: Path | None = None
    workers: int | None = None
    timestamps: Path | None = None
    fps: float | None = None
    target: MarkerTarget | None = None
    selection: FrameSelection = field(default_factory=FrameSelection)
    topic: str | None = None


@dataclass(frozen=True)
class PosesRun:
    """What :func:`run_poses` did."""

    trajectory: Trajectory
    reprojection_rms: np.ndarray
    skipped: list[str]
    output: Path
    cached: int
    warnings: list[str] = field(default_factory=list)


class _TimeOptions(Protocol):
    """The stage options that say where image times come from."""

    @property
    def timestamps(self) -> Path | None: ...

    @property
    def fps(self) -> float | None: ...


def _time_source(config: _TimeOptions) -> dict[str, int] | None:
    """The ``--timestamps`` file read (before any work), with ``--fps`` checked against it."""
    if config.timestamps is not None and config.fps is not None:
        raise InputError("give either --timestamps or --fps, not both")
    if config.fps is not None and not (np.isfinite(config.fps) and config.fps > 0):
        raise InputError(f"--fps must be a positive frame rate, got {config.fps}")
    return None if config.timestamps is None else read_timestamps_file(config.timestamps)


def _image_times(
    names: list[str], all_names: list[str], stamps: dict[str, int] | None, config: _TimeOptions
) -> ImageTimes:
    return image_times(
        names,
        all_names,
        timestamps=stamps,
        timestamps_source=str(config.timestamps),
        fps=config.fps,
    )


def _trajectory(
    times: ImageTimes, T_world_cam: np.ndarray, names: list[str], output: Path
) -> Trajectory:
    """The posed images' trajectory, with their times as :func:`_image_times` gave them."""
    return Trajectory(
        times.seconds,
        T_world_cam,
        source=str(output),
        format="npz",
        has_timestamps=times.has_timestamps,
        names=tuple(names),
        timestamps_ns=times.nanoseconds,
        time_unit=times.unit,
    )


def _tum_note(times: ImageTimes) -> str | None:
    """The TUM file's comment when its times are frame numbers."""
    return None if times.unit == "s" else f"{FRAME_NUMBERS_NOTE} ({times.source}), not seconds"


def _time_header(header: dict[str, Any], times: ImageTimes) -> None:
    header["timestamps_from"] = times.source
    header["units"]["timestamps"] = "s" if times.unit == "s" else "frame number (not seconds)"


def _poses_target(
    config: PosesConfig, cam: IntrinsicsArtifact, intrinsics: Path
) -> MarkerTarget | None:
    """The AprilGrid or ChArUco to pose on: the option's, else the intrinsics' (unless a
    checkerboard option is given); None for a checkerboard."""
    opts = {"--board": config.cols, "--square": config.square}
    given = [k for k, v in opts.items() if v is not None]
    if config.target is not None:
        if given:
            raise InputError(
                f"{' and '.join(given)} {'describe' if len(given) > 1 else 'describes'} a "
                "checkerboard; --target replaces them"
            )
        return config.target
    if cam.target is None or given:
        return None
    target = target_from_mapping(cam.target, intrinsics, "target")
    return None if isinstance(target, Checkerboard) else target


def video_times(ns: list[int], bag: bool = False) -> ImageTimes:
    """The times of a video's frames: their presentation timestamps (integer ns); of a
    bag's images (``bag``): their ``header.stamp``."""
    return times_from_ns(ns, "the images' header.stamp (ROS bag)" if bag else VIDEO_TIMES)


def _video_times_check(images: Path, config: _TimeOptions) -> bool:
    """True for a video input; :class:`InputError` when ``--timestamps``/``--fps`` are
    given for one (its frames carry their own times)."""
    if not (is_video_path(images) or is_bag_path(images)):
        return False
    given = [
        k for k, v in (("--timestamps", config.timestamps), ("--fps", config.fps)) if v is not None
    ]
    if given:
        raise InputError(
            f"{' and '.join(given)} {'apply' if len(given) > 1 else 'applies'} to image "
            "folders: a video's frames carry their own times (presentation timestamps); "
            "leave it out",
            path=images,
        )
    return True


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
        intrinsics', markers of another family than the target's.
    DegenerateMotionError
        No image shows enough of an AprilGrid or ChArUco target for a pose.
    """
    cam = IntrinsicsArtifact.load(intrinsics)
    stamps = _time_source(config)
    target = _poses_target(config, cam, intrinsics)
    cols, rows, square = 0, 0, 0.0  # the checkerboard's; unused with a target
    if target is None:
        board = cam.board or BoardSpec()
        cols = int(_board_option(config.cols, board.cols, "size", intrinsics))
        rows = int(_board_option(config.rows, board.rows, "size", intrinsics))
        square = float(_board_option(config.square, board.square, "square", intrinsics))
        if cols < 2 or rows < 2:
            raise InputError(f"--board needs at least 2x2 inner corners, got {cols}x{rows}")
        if not (np.isfinite(square) and square > 0):
            raise InputError(f"--square must be a positive length in metres, got {square}")
    _video_times_check(images_dir, config)
    config.selection.check()
    outputs = [output] + ([config.tum] if config.tum is not None else [])
    inputs = [intrinsics, *input_files(images_dir)]
    for o in outputs:
        check_distinct_output(o, inputs)
    if config.tum is not None and os.path.realpath(config.tum) == os.path.realpath(output):
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
        target=target,
        selection=config.selection,
        topic=config.topic,
    )
    if fd.image_size != cam.image_size:
        raise InputError(
            f"images are {fd.image_size[0]}x{fd.image_size[1]} but {intrinsics.name} was "
            f"calibrated at {cam.image_size[0]}x{cam.image_size[1]}",
            path=images_dir,
        )
    obj = board_points(cols, rows, square) if target is None else target.points()
    all_names = [p.name for p in fd.images]
    names: list[str] = []
    T_cb: list[np.ndarray] = []
    rms: list[float] = []
    corners: list[np.ndarray] = []
    skipped: list[str] = []
    for p, d in zip(fd.images, fd.detections, strict=True):
        pose = None
        if d.found and d.corners is not None and target is None:
            pose = board_pose(obj, d.corners, cam.camera_matrix, cam.distortion, cam.model)
        elif d.found and d.corners is not None:  # identified corners, NaN where unseen
            seen = np.all(np.isfinite(d.corners), axis=1)
            if pose_ready(obj[seen]):
                pose = board_pose(
                    obj[seen], d.corners[seen], cam.camera_matrix, cam.distortion, cam.model
                )
        if pose is None or d.corners is None:
            skipped.append(p.name)
            continue
        names.append(p.name)
        T_cb.append(pose.T_cam_board)
        rms.append(pose.rms_px)
        corners.append(np.asarray(d.corners, dtype=float).reshape(-1, 2))
    if not names and target is not None:
        n_some = sum(d.found for d in fd.detections)
        raise no_target_error(images_dir, target, fd.images, n_some)
    board_note = None
    if target is None:  # a wrong --board is named (exit 2) rather than posing a few images
        board_note = few_boards(images_dir, fd, cols, rows, 1, part_is_error=True)
    if not names:
        raise no_board_error(images_dir, cols, rows, len(fd.images))
    if fd.times_ns is not None:
        by_name = dict(zip(all_names, fd.times_ns, strict=True))
        times = video_times([by_name[n] for n in names], bag=config.topic is not None)
    else:
        times = _image_times(names, all_names, stamps, config)
    t = times.seconds
    warnings = [*fd.notes] + [w for w in (board_note, times.note) if w is not None]
    # one board frame for the whole sequence: undo 180-degree relabellings of the board
    T_cb_arr = np.stack(T_cb)
    if target is None and cols != rows:
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
    traj = _trajectory(times, T_wc, names, output)
    if skipped:
        warnings.append(f"no board pose in {len(skipped)} image(s): {', '.join(skipped[:10])}")
    header = make_header(
        "poses",
        {_input_role(fd): images_dir, "intrinsics": intrinsics},
        method="cv2.solvePnP (SOLVEPNP_IPPE) refined by cv2.solvePnPRefineLM on "
        f"{cols}x{rows} board corners; T_world_cam = inverse of T_cam_board",
        units={"length": "m", "reprojection_rms": "px"},
        frames={
            "world": "the board (origin at its first inner corner, z into the board)",
            "cam": "the camera's optical frame",
        },
    )
    if target is None:
        header["board"] = {"cols": cols, "rows": rows, "square": square, "units": "m"}
    else:
        header["method"] = (
            "cv2.solvePnP (SOLVEPNP_IPPE) refined by cv2.solvePnPRefineLM on each image's "
            f"identified {target.kind} corners (at least {MIN_POSE_CORNERS}, not collinear); "
            "T_world_cam = inverse of T_cam_target; corners (n, m, 2) hold NaN where a corner "
            "was not seen"
        )
        header["frames"]["world"] = f"the target: {TARGET_FRAMES[target.kind]}"
        header["target"] = target_to_mapping(target)
    header["intrinsics_file"] = str(intrinsics)
    _time_header(header, times)
    if fd.frames is not None:
        header["video"] = fd.frames
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
        write_tum(config.tum, t, T_wc, timestamps_ns=times.nanoseconds, note=_tum_note(times))
    return PosesRun(traj, rms_arr, skipped, output, fd.cached, warnings)


# --------------------------------------------------------------------------------------
# markerless: structure from motion

#: The file that marks a ``--workdir`` as made by ``acscal poses --sfm`` (safe to clear).
WORKDIR_MARKER = ".acscal-sfm"
#: What ``run_sfm_poses`` clears in a work folder it made before (COLMAP's files).
_WORKDIR_ENTRIES = ("images", "frames", "sparse", "database.db", "vocab_tree.bin", "vocab_tree.log")
#: Below this registered fraction the warning says the trajectory has gaps worth a look.
POOR_REGISTRATION = 0.9


@dataclass(frozen=True)
class SfmPosesConfig:
    """Options of the markerless poses stage (``acscal poses --sfm``).

    Attributes
    ----------
    tum : Path, optional
        Also write the trajectory as a TUM file.
    workers : int, optional
        Threads of COLMAP's extraction, matching and mapping (default: all cores).
    matching : {"auto", "sequential", "exhaustive"}
        See :class:`acs_cli.core.sfm.SfmOptions`.
    loop_closure : bool
        Sequential matching also looks for the sequence's returns to places it has seen.
    vocab_tree : Path, optional
        A COLMAP 4 vocabulary tree for loop closure (default: trained on the sequence).
    refine_intrinsics : bool
        Refine the given intrinsics' focal lengths and distortion (needs ``intrinsics``).
    max_image_size : int, optional
        Downscale larger images to this many pixels on their longer side for features.
    max_features : int
        Most SIFT features per image.
    workdir : Path, optional
        Keep COLMAP's database and models there (an empty or new folder, or one an earlier
        ``--sfm`` run made); default: a temporary folder, removed afterwards.
    timestamps, fps
        As :class:`PosesConfig`'s.
    selection : FrameSelection
        The frames of a video or a bag used.
    topic : str, optional
        A ROS bag's image topic (its ``header.stamp`` are the times).
    """

    tum: Path | None = None
    workers: int | None = None
    matching: str = "auto"
    loop_closure: bool = True
    vocab_tree: Path | None = None
    refine_intrinsics: bool = False
    max_image_size: int | None = None
    max_features: int = 8192
    workdir: Path | None = None
    timestamps: Path | None = None
    fps: float | None = None
    selection: FrameSelection = field(default_factory=FrameSelection)
    topic: str | None = None


@dataclass(frozen=True)
class SfmPosesRun:
    """What :func:`run_sfm_poses` did: the trajectory written, the SfM result, warnings."""

    trajectory: Trajectory
    result: SfmResult
    output: Path
    warnings: list[str] = field(default_factory=list)

    @property
    def reprojection_rms(self) -> np.ndarray:
        """RMS reprojection error of each posed image, pixels, shape (n,)."""
        return self.result.reprojection_rms_per_image


@contextlib.contextmanager
def _sfm_workdir(path: Path | None, protected: list[Path]) -> Iterator[Path]:
    """COLMAP's work folder: a temporary one, or ``path`` made ready (and kept).

    ``path`` must be new, empty, or marked by an earlier run (whose COLMAP files are then
    removed); a folder holding anything else is refused, and so is one of ``protected``.
    """
    if path is None:
        with tempfile.TemporaryDirectory(prefix="acscal-sfm-") as tmp:
            yield Path(tmp)
        return
    work = Path(path)
    for p in protected:
        with contextlib.suppress(OSError):
            if work.resolve() == Path(p).resolve():
                raise InputError(f"--workdir must not be {p}", path=work)
    if work.exists() and not work.is_dir():
        raise InputError("--workdir is a file, expected a folder", path=work)
    try:
        work.mkdir(parents=True, exist_ok=True)
        entries = [e.name for e in work.iterdir()]
    except OSError as exc:
        raise InputError(f"cannot use --workdir ({exc.strerror or exc})", path=work) from exc
    if entries and WORKDIR_MARKER not in entries:
        raise InputError(
            "--workdir is not empty and was not made by `acscal poses --sfm`; give an empty "
            "or new folder",
            path=work,
        )
    try:
        for name in entries:
            entry = work / name
            if name in _WORKDIR_ENTRIES or name.startswith("colmap.log"):
                if entry.is_dir() and not entry.is_symlink():
                    shutil.rmtree(entry)
                else:
                    entry.unlink()
            elif name.startswith("database.db-"):  # SQLite's journal files
                entry.unlink()
        (work / WORKDIR_MARKER).write_text(
            "COLMAP work folder of `acscal poses --sfm`; a rerun clears it\n", encoding="utf-8"
        )
    except OSError as exc:
        raise InputError(f"cannot prepare --workdir ({exc.strerror or exc})", path=work) from exc
    yield work


def _sfm_camera(intrinsics: Path) -> SfmCamera:
    """The camera of an intrinsics file, checked for COLMAP (an InputError names the file)."""
    from acs_cli.core.sfm import colmap_camera

    cam = IntrinsicsArtifact.load(intrinsics)
    sfm_cam = SfmCamera(
        cam.model,
        (int(cam.image_size[0]), int(cam.image_size[1])),
        np.asarray(cam.camera_matrix, dtype=float),
        np.asarray(cam.distortion, dtype=float),
    )
    try:
        colmap_camera(sfm_cam)
    except InputError as exc:
        raise InputError(exc.message, path=intrinsics) from exc
    return sfm_cam


def _video_frames_to(
    video: Path,
    folder: Path,
    selection: FrameSelection,
    progress: SfmProgress | None,
    topic: str | None = None,
) -> tuple[tuple[int, int], dict[str, int], list[str], dict[str, Any]]:
    """Decode a video's (a bag's ``topic``'s) kept frames into ``folder`` as PNG files
    (``frame_000123.png``), one at a time; their size, their times (ns) by file name, the
    reader's notes and the frame counts (for the header)."""
    report = VideoRead()
    times: dict[str, int] = {}
    size: tuple[int, int] | None = None
    folder.mkdir(parents=True, exist_ok=True)
    frames = (
        read_bag_frames(video, topic, selection, report)
        if is_bag_path(video)
        else read_video_frames(video, selection, report)
    )
    for k, frame in enumerate(frames):
        got = (int(frame.image.shape[1]), int(frame.image.shape[0]))
        size = size or got
        if got != size:  # pragma: no cover - one stream has one size
            raise InputError(f"{frame.ref.name} is {got[0]}x{got[1]}", path=video)
        ok, png = cv2.imencode(".png", frame.image)
        if not ok:  # pragma: no cover - encoding a grey array does not fail
            raise InputError(f"cannot encode {frame.ref.name} as PNG", path=video)
        name = frame.ref.name + ".png"
        atomic_write_bytes(folder / name, png.tobytes())
        times[name] = frame.ref.time_ns
        if progress is not None:
            progress("decoding video", k + 1, max(k + 1, report.estimate or report.count or 0))
    if size is None:  # pragma: no cover - read_video_frames raises first
        raise InputError("no frame of the video decodes", path=video)
    notes, counts = report.outcome(selection, len(times))
    if topic is not None:
        counts["topic"] = topic
    return size, times, notes, counts


def _check_images(paths: list[Path], progress: SfmProgress | None) -> tuple[int, int]:
    """Read every image (a missing or corrupt one is an InputError naming it); one size."""
    size: tuple[int, int] | None = None
    for i, p in enumerate(paths):
        if progress is not None and i % 10 == 0:
            progress("reading images", i, len(paths))
        img, _ = read_gray(p)
        got = (int(img.shape[1]), int(img.shape[0]))
        if size is None:
            size = got
        elif got != size:
            raise InputError(
                f"image size {got[0]}x{got[1]} differs from {size[0]}x{size[1]} of "
                f"{paths[0].name}: all images must come from one camera at one resolution",
                path=p,
            )
    if progress is not None:
        progress("reading images", len(paths), len(paths))
    if size is None:  # list_images never returns an empty list
        raise InputError("no images", path=paths[0].parent if paths else None)
    return size


#: Refined intrinsics that moved more than this (relative focal length, or fx/fy ratio
#: by a fifth of it) from the given ones get a warning.
REFINED_DRIFT = 0.1


def _sfm_warnings(result: SfmResult, given: SfmCamera | None = None) -> list[str]:
    """Self-calibration, intrinsics that drifted when refined, unregistered and dropped
    images, notes of the reconstruction."""
    warnings: list[str] = []
    n = len(result.image_names)
    cam = result.camera
    if given is not None and result.intrinsics_refined:
        f0 = np.diag(given.camera_matrix)[:2]
        f1 = np.diag(cam.camera_matrix)[:2]
        change = np.abs(f1 / f0 - 1.0)
        aspect = abs((f1[0] / f1[1]) / (f0[0] / f0[1]) - 1.0)
        if change.max() > REFINED_DRIFT or aspect > REFINED_DRIFT / 5:
            warnings.append(
                f"the refined intrinsics moved far from the given ones (fx {f0[0]:.1f} -> "
                f"{f1[0]:.1f}, fy {f0[1]:.1f} -> {f1[1]:.1f} px): this motion does not "
                "determine them (e.g. a camera turning about one axis only), and the "
                "trajectory may be distorted with them; rerun without --refine-intrinsics"
            )
    if result.intrinsics_source == "self-calibrated":
        K = cam.camera_matrix
        warnings.append(
            "no --intrinsics: COLMAP self-calibrated one camera for the whole folder "
            f"({result.colmap_model}: f {K[0, 0]:.1f} px, cx {K[0, 2]:.1f}, cy {K[1, 2]:.1f} "
            f"px, k1 {cam.distortion[0]:+.4f}; recorded in the NPZ); poses are more reliable "
            "with a calibration: `acscal intrinsics` (--model fisheye for a wide-angle "
            "action camera), then --intrinsics"
        )
    unregistered = result.unregistered_names
    missing = [x for x in unregistered if x not in set(result.dropped_images)]
    if missing:
        frac = 1.0 - len(unregistered) / n
        gaps = " (the trajectory has gaps)" if frac < POOR_REGISTRATION else ""
        warnings.append(
            f"{len(missing)} of {n} images were not registered and have no pose{gaps}: "
            f"{', '.join(missing[:10])}" + (", ..." if len(missing) > 10 else "")
        )
    if result.num_models > 1:
        dropped = result.dropped_images
        warnings.append(
            f"the reconstruction split into {result.num_models} models (registered images: "
            f"{', '.join(map(str, result.model_sizes))}); kept the largest and dropped "
            f"{len(dropped)} image(s) of the others"
            + (f": {', '.join(dropped[:10])}" if dropped else "")
            + (", ..." if len(dropped) > 10 else "")
            + "; frames between the models probably lack overlap (fast motion, blur, a "
            "blank view)"
        )
    warnings += result.notes
    return warnings


def run_sfm_poses(
    images_dir: Path,
    intrinsics: Path | None,
    output: Path,
    config: SfmPosesConfig,
    progress: SfmProgress | None = None,
) -> SfmPosesRun:
    """Structure from motion on an image sequence; write the ``acscal/poses`` NPZ.

    Parameters
    ----------
    images_dir : Path
        The folder of the sequence (natural order of file names = time order).
    intrinsics : Path, optional
        An ``acscal/intrinsics`` file (held fixed unless ``config.refine_intrinsics``);
        ``None``: COLMAP self-calibrates the camera (with a warning).
    output : Path
        The poses NPZ: ``T_world_cam`` (n, 4, 4) of the registered images, world = the
        first registered camera's frame, translations in SfM units (unknown scale), and
        the ``sfm_*`` arrays (:class:`acs_cli.io.poses.SfmSummary`).
    config : SfmPosesConfig
    progress : callable, optional
        ``progress(phase, done, total)``.

    Returns
    -------
    SfmPosesRun

    Raises
    ------
    InputError
        A missing, empty or corrupt image folder or image, images of several sizes, a bad
        intrinsics file (or one of another image size, or a model COLMAP cannot use),
        ``refine_intrinsics`` without intrinsics, an unusable ``--workdir`` or output.
    DegenerateMotionError
        A sequence SfM cannot reconstruct (too few images, blank or textureless frames,
        nothing registered); nothing is written.
    """
    from acs_cli.core.sfm import pycolmap_version, run_sfm

    if config.refine_intrinsics and intrinsics is None:
        raise InputError("--refine-intrinsics needs --intrinsics (a calibration to refine)")
    stamps = _time_source(config)
    bag = is_bag_path(images_dir)
    if config.topic is not None and not bag:
        raise InputError(f"--topic ({config.topic}) applies to ROS bags", path=images_dir)
    video = _video_times_check(images_dir, config)
    config.selection.check()
    if not video and not config.selection.trivial:
        raise InputError(
            "--every, --max-frames, --skip-blurred and --min-change select frames of a video "
            "file; this is a folder of images",
            path=images_dir,
        )
    paths = [] if video else list_images(images_dir)
    camera = _sfm_camera(intrinsics) if intrinsics is not None else None
    opts = SfmOptions(
        matching=config.matching,
        loop_closure=config.loop_closure,
        vocab_tree=config.vocab_tree,
        refine_intrinsics=config.refine_intrinsics,
        max_image_size=config.max_image_size,
        max_features=config.max_features,
        threads=config.workers,
    )
    outputs = [output] + ([config.tum] if config.tum is not None else [])
    inputs = [images_dir, *paths] + ([intrinsics] if intrinsics is not None else [])
    for o in outputs:
        check_distinct_output(o, inputs)
    if config.tum is not None and os.path.realpath(config.tum) == os.path.realpath(output):
        raise InputError("--tum and -o name the same file", path=output)
    for o in outputs:
        check_writable(o)
    frame_ns: dict[str, int] = {}
    notes: list[str] = []
    counts: dict[str, Any] = {}
    with _sfm_workdir(config.workdir, [images_dir, output.parent]) as work:
        folder = images_dir
        if video:  # COLMAP reads files: the kept frames go to the work folder, as PNG
            folder = work / "frames"
            size, frame_ns, notes, counts = _video_frames_to(
                images_dir, folder, config.selection, progress, config.topic
            )
            all_names = list(frame_ns)
        else:
            size = _check_images(paths, progress)
            all_names = [p.name for p in paths]
        if camera is not None and size != camera.image_size:
            raise InputError(
                f"images are {size[0]}x{size[1]} but {intrinsics} was calibrated at "
                f"{camera.image_size[0]}x{camera.image_size[1]}",
                path=images_dir,
            )
        result = run_sfm(folder, all_names, work, camera, opts, progress)

    names = list(result.registered_names)
    if video:
        times = video_times([frame_ns[n] for n in names], bag=bag)
    else:
        times = _image_times(names, all_names, stamps, config)
    traj = _trajectory(times, result.T_world_cam, names, output)
    warnings = notes + _sfm_warnings(result, camera)
    warnings += [] if times.note is None else [times.note]
    cam = result.camera
    given = "given (" + ("refined" if result.intrinsics_refined else "held fixed") + ")"
    n_images = len(all_names)
    header = make_header(
        "poses",
        {("bag" if bag else "video") if video else "images": images_dir}
        | ({"intrinsics": intrinsics} if intrinsics is not None else {}),
        method=(
            f"incremental structure from motion ({pycolmap_version()}): SIFT features, "
            f"{result.matching} matching"
            + (f" with loop closure ({result.loop_closure})" if result.loop_pairs else "")
            + ", COLMAP's incremental mapper with one shared "
            f"{result.colmap_model} camera, intrinsics "
            + (given if result.intrinsics_source == "given" else "self-calibrated")
            + "; the largest model kept; T_world_cam = inverse of cam_from_world, world = the "
            "first registered camera, unit = mean distance between consecutive registered "
            "camera centres"
        ),
        units={
            "length": "SfM units (unknown scale: mean distance between consecutive registered "
            "camera centres = 1)",
            "reprojection_rms": "px",
            "camera_matrix": "px",
        },
        frames={
            "world": "the first registered image's camera frame (SfM fixes the world only up "
            "to a similarity)",
            "cam": "the camera's optical frame",
        },
    )
    if intrinsics is not None:
        header["intrinsics_file"] = str(intrinsics)
    _time_header(header, times)
    header["front_end"] = "sfm"
    if video:
        header["video"] = counts
    feats = result.features_per_image
    header["sfm"] = {
        "method": "incremental",
        "software": pycolmap_version(),
        "matching": result.matching,
        "loop_closure": result.loop_closure,
        "loop_pairs": result.loop_pairs,
        "verified_pairs": result.verified_pairs,
        "parallax_deg": round(result.parallax_deg, 4),
        "options": result.options,
        "camera": {
            "colmap_model": result.colmap_model,
            "colmap_params": list(result.colmap_params),
            "colmap_pixel_convention": "centre of the top-left pixel at (0.5, 0.5)",
            "model": cam.model,
            "source": result.intrinsics_source,
            "refined": result.intrinsics_refined,
        },
        "registered": int(result.registered.sum()),
        "images": n_images,
        "model_sizes": list(result.model_sizes),
        "features_per_image": {
            "min": int(feats.min()),
            "median": float(np.median(feats)),
            "max": int(feats.max()),
        },
        "seconds": {k: round(v, 3) for k, v in result.seconds.items()},
        "seconds_per_image": round(result.seconds.get("total", 0.0) / n_images, 4),
        "workdir": None if config.workdir is None else str(config.workdir),
    }
    header["warnings"] = warnings
    summary = SfmSummary(
        images=tuple(all_names),
        registered=result.registered,
        dropped_images=result.dropped_images,
        num_models=result.num_models,
        num_points3d=result.num_points3d,
        mean_track_length=result.mean_track_length,
        reprojection_rms=result.reprojection_rms,
        camera_matrix=cam.camera_matrix,
        distortion=cam.distortion,
        intrinsics_model=cam.model,
        intrinsics_source=result.intrinsics_source,
        intrinsics_refined=result.intrinsics_refined,
        image_size=cam.image_size,
    )
    PosesArtifact(
        trajectory=traj,
        reprojection_rms=result.reprojection_rms_per_image,
        skipped_images=result.unregistered_names,
        metric_scale=False,
        sfm=summary,
        header=header,
    ).save(output)
    if config.tum is not None:
        write_tum(
            config.tum,
            times.seconds,
            result.T_world_cam,
            timestamps_ns=times.nanoseconds,
            note=_tum_note(times),
        )
    return SfmPosesRun(traj, result, output, warnings)
