"""The intrinsics stage: ``acscal intrinsics`` (checkerboard detection + OpenCV calibration).

:func:`detect_folder` (shared with the poses stage) detects the board in every image of a
folder, in parallel, reusing and incrementally updating a detections cache;
:func:`run_intrinsics` calibrates from the detections and writes the artifact.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from acs_cli.core.checkerboard import DETECTOR_VERSION, corner_spacing_px, detect_checkerboard
from acs_cli.core.intrinsics import (
    DISTORTION_NAMES,
    MIN_VIEWS,
    MODELS,
    CalibrationResult,
    board_points,
    calibrate_robust,
    degenerate_distortion,
    honest_std,
    intrinsics_covariance,
)
from acs_cli.core.quality import intrinsics_measures, judge
from acs_cli.core.targets import (
    MIN_POSE_CORNERS,
    TARGETS_DETECTOR_VERSION,
    MarkerTarget,
    detect_target,
    find_other_family,
    pose_ready,
)
from acs_cli.errors import AcsError, DegenerateMotionError, InputError
from acs_cli.io.artifacts import make_header, to_plain
from acs_cli.io.atomic import check_distinct_output, check_writable, file_sha256
from acs_cli.io.bag import bag_key, is_bag_path, read_bag_frames, read_bag_images
from acs_cli.io.detections import (
    Detection,
    cache_path_for,
    detection_key,
    read_detections,
    write_detections,
)
from acs_cli.io.export import (
    check_ros_camera_name,
    opencv_camera_values,
    write_opencv_yaml,
    write_ros_camera_info,
)
from acs_cli.io.images import list_images, read_gray
from acs_cli.io.intrinsics import BoardSpec, DroppedView, ImagesUsed, IntrinsicsArtifact
from acs_cli.io.target import target_to_mapping
from acs_cli.io.verdict import VerdictSection, weak_marks
from acs_cli.io.video import (
    EVERY_FRAME,
    FrameSelection,
    VideoFrame,
    VideoRead,
    is_video_path,
    read_frame_images,
    read_video_frames,
    video_sha256,
)

__all__ = [
    "EXPORTS",
    "FolderDetections",
    "IntrinsicsConfig",
    "IntrinsicsRun",
    "detect_folder",
    "no_board_error",
    "run_intrinsics",
    "write_ros_camera_info",  # re-exported from acs_cli.io.export
]

EXPORTS = ("ros", "opencv")
#: Detections between two cache snapshots during a run.
CACHE_EVERY = 16
#: Images below which detection runs in this process (a pool costs more than it saves).
MIN_IMAGES_PER_WORKER = 12

Progress = Callable[[int, int], None]
#: An image of the input: a file of a folder, or a frame of a video.
ImageRef = Path | VideoFrame


def read_images(refs: Sequence[ImageRef]) -> list[np.ndarray]:
    """The greyscale pixels of some images of one input (a video's frames in one pass)."""
    frames = [r for r in refs if isinstance(r, VideoFrame)]
    read = read_bag_images if frames and frames[0].topic is not None else read_frame_images
    decoded = dict(zip([f.index for f in frames], read(frames), strict=True))
    return [decoded[r.index] if isinstance(r, VideoFrame) else read_gray(r)[0] for r in refs]


def ref_path(ref: ImageRef) -> Path:
    """The file an image comes from (a video frame's video)."""
    return ref.video if isinstance(ref, VideoFrame) else ref


def _input_role(fd: FolderDetections) -> str:
    """The header's name of the input: ``images``, ``video`` or ``bag``."""
    if fd.frames is None:
        return "images"
    return "bag" if "topic" in fd.frames else "video"


def input_files(images: Path) -> list[Path]:
    """The input files an output must not overwrite: the folder and its images, or the
    video."""
    if is_video_path(images) or is_bag_path(images):
        return [images]
    return [images, *list_images(images)]


@dataclass(frozen=True)
class IntrinsicsConfig:
    """Options of the intrinsics stage.

    Attributes
    ----------
    cols, rows : int
        Inner corners of the board along its x axis and its y axis.
    square : float
        Square side, metres.
    model : {"pinhole", "rational", "fisheye"}
    export : tuple of str
        Extra files: ``"ros"`` (camera_info YAML), ``"opencv"`` (cv2.FileStorage YAML).
    camera_name : str
        ``camera_name`` of the ROS camera_info (camera_info_manager's default, ``camera``).
    workers : int, optional
        Detection processes (default ``os.cpu_count()``).
    target : AprilGrid or Charuco, optional
        Calibrate on this target (identified corners, partial views) instead of the
        ``cols x rows`` checkerboard.
    """

    cols: int = 9
    rows: int = 6
    square: float = 0.025
    model: str = "pinhole"
    export: tuple[str, ...] = ()
    camera_name: str = "camera"
    workers: int | None = None
    target: MarkerTarget | None = None
    accept_weak: bool = False
    selection: FrameSelection = field(default_factory=FrameSelection)
    topic: str | None = None


@dataclass(frozen=True)
class FolderDetections:
    """Detections of the board in a folder's images.

    Attributes
    ----------
    images : list of Path or VideoFrame
        All images, in natural order (a video's kept frames, in its order).
    detections : list of Detection
        One per image, same order.
    image_size : tuple of int
        ``(width, height)`` shared by all images, pixels.
    cached : int
        How many detections came from a cache.
    cache : Path
        The cache file written.
    times_ns : list of int, optional
        A video's frame times (presentation timestamps, integer nanoseconds); None for a
        folder.
    notes : list of str
        A video's selection counts and damage, as warnings.
    frames : dict, optional
        A video's counts for artifacts: ``decoded``, ``kept``, ``selection``.
    keys : list of str
        Each image's key in the detections cache (same order).
    """

    images: Sequence[ImageRef]
    detections: list[Detection]
    image_size: tuple[int, int]
    cached: int
    cache: Path
    times_ns: list[int] | None = None
    notes: list[str] = field(default_factory=list)
    frames: dict[str, Any] | None = None
    keys: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class IntrinsicsRun:
    """What :func:`run_intrinsics` did."""

    calibration: CalibrationResult
    artifact: dict[str, Any]
    output: Path
    exports: dict[str, Path]
    detections: FolderDetections
    warnings: list[str] = field(default_factory=list)


#: Folders of at most this many images have each board's larger-board screen score
#: (:attr:`Detection.extension`) measured by the detection (about 1.5 ms a large image),
#: so that the check reads no image again (about 0.1 s for its four); larger folders skip
#: it and the check reads its four images. Video frames are always measured: the check would
#: seek and decode them again.
MEASURE_EXTENSION_UP_TO = 100


def _detect_file(
    path: str, cols: int, rows: int, target: MarkerTarget | None = None, measure: bool = True
) -> tuple[str, Detection | None, str | None]:
    """Worker: read one image and detect the board (or ``target``, an AprilGrid or ChArUco:
    corners ``(m, 2)`` by id, NaN where unseen); errors come back as text."""
    try:
        img, sha = read_gray(path)
    except InputError as exc:
        return "", None, exc.one_line()
    return _detect_image(img, Path(path).name, sha, cols, rows, target, measure)


def _detect_image(
    img: np.ndarray,
    name: str,
    sha: str,
    cols: int,
    rows: int,
    target: MarkerTarget | None,
    measure: bool = True,
) -> tuple[str, Detection | None, str | None]:
    """Worker: detect the board (or ``target``) in one greyscale image whose content key is
    ``sha``; with ``measure``, a board's larger-board screen score too."""
    h, w = img.shape[:2]
    if target is not None:
        found = detect_target(img, target)
        dense = found.dense(target.n_corners) if len(found) else None
        det = Detection(name, dense is not None, (int(w), int(h)), dense)
        return _target_key(sha, target), det, None
    corners = detect_checkerboard(img, cols, rows)
    score = _extension(img, corners, cols, rows) if measure else None
    det = Detection(name, corners is not None, (int(w), int(h)), corners, score)
    return detection_key(sha, cols, rows, DETECTOR_VERSION), det, None


def _extension(img: np.ndarray, corners: np.ndarray | None, cols: int, rows: int) -> float | None:
    """A board's larger-board screen score (:attr:`Detection.extension`), or None."""
    from acs_cli.core.board_hint import extension_score

    return None if corners is None else extension_score(img, corners, cols, rows)


def _target_key(sha: str, target: MarkerTarget) -> str:
    """The detections-cache key of an AprilGrid or ChArUco target (identified corners)."""
    label = target.short().replace(":", "/") + f"#{target.n_corners}"
    return f"{sha}:{label}:{TARGETS_DETECTOR_VERSION}"


def _init_worker(parent: int) -> None:
    """Pool initializer: end this worker when its parent dies.

    A killed ``acscal`` (SIGKILL, the OOM killer) cannot shut its pool down, and the
    workers would otherwise wait for work forever.

    It must not touch OpenCV's threads (``cv2.setNumThreads``): a worker is forked from a
    process whose OpenCV thread pool may be busy (a video's first frames are detected in
    the process), and the fork's copy of that pool's lock then never opens (a worker that
    set one thread hung without ever starting: `tests/io/test_images.py`).
    """
    import threading

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _detection_pool(n_workers: int) -> ProcessPoolExecutor:
    """A pool of ``n_workers`` detection processes (:func:`_init_worker`).

    ``numpy.ma`` is imported here first: ``np.median`` imports it on its first call (25 ms),
    which every forked worker would otherwise do on its first board; this process needs it
    anyway (the outlier views' median).
    """
    import numpy.ma  # noqa: F401

    return ProcessPoolExecutor(n_workers, initializer=_init_worker, initargs=(os.getpid(),))


def _worker_count(workers: int | None) -> int:
    """Detection processes asked for: ``workers``, by default one per core."""
    return max(1, int(workers if workers is not None else (os.cpu_count() or 1)))


def _pool_size(workers: int | None, n_images: int) -> int:
    """Processes for ``n_images`` images to detect (1: no pool, they run in this process)."""
    return min(_worker_count(workers), max(1, n_images // MIN_IMAGES_PER_WORKER))


def _file_key(path: Path, cols: int, rows: int, target: MarkerTarget | None = None) -> str:
    sha = file_sha256(path, "image")
    if target is not None:
        return _target_key(sha, target)
    return detection_key(sha, cols, rows, DETECTOR_VERSION)


def no_board_error(
    folder: Path, cols: int, rows: int, n: int, advice: str | None = None
) -> InputError:
    """The error for a folder where no image shows the board (``advice``: from
    :func:`board_advice`)."""
    return InputError(
        f"no {cols}x{rows} board found in any of {n} images; "
        + (advice or "check --board (inner corners, COLSxROWS)"),
        path=folder,
    )


#: Images without the board that :func:`board_advice` tries nearby sizes on.
HINT_IMAGES = 4
#: Below this share of images with the board, the board size is checked (and named).
FEW_BOARDS = 0.5


def board_advice(
    images: Sequence[ImageRef], cols: int, rows: int
) -> tuple[str, tuple[int, int] | None]:
    """Advice naming ``--board`` for images where a ``cols x rows`` board was not found,
    and the nearby size they show, if one is found in them
    (:func:`acs_cli.core.board_hint.board_size_hint` on up to :data:`HINT_IMAGES` of them)."""
    from acs_cli.core.board_hint import nearby_board_sizes

    found = _size_in(images, nearby_board_sizes(cols, rows))
    if found is None:
        return (
            "check --board: it counts inner corners (squares minus one), COLSxROWS, and the "
            "whole board must be in view",
            None,
        )
    (c, r), k = found
    return (
        f"the images show a {c}x{r} board (found in {k} of {min(len(images), HINT_IMAGES)} "
        f"images tried where {cols}x{rows} was not): give --board {c}x{r} (inner corners)",
        (c, r),
    )


def _spread(n: int) -> list[int]:
    """Up to :data:`HINT_IMAGES` indices of ``n`` items, evenly spread: the images the
    board-size checks look at."""
    return [int(i) for i in np.unique(np.round(np.linspace(0, n - 1, HINT_IMAGES)))]


def _size_in(
    images: Sequence[ImageRef], sizes: Sequence[tuple[int, int]]
) -> tuple[tuple[int, int], int] | None:
    """:func:`acs_cli.core.board_hint.board_size_hint` on up to :data:`HINT_IMAGES` of
    ``images``, evenly spread."""
    from acs_cli.core.board_hint import board_size_hint

    if not images:
        return None
    return board_size_hint(read_images([images[i] for i in _spread(len(images))]), sizes)


def _larger_ruled_out(
    images: Sequence[ImageRef], detections: Sequence[Detection], cols: int, rows: int
) -> tuple[bool, list[np.ndarray] | None]:
    """Whether the images' own pixels rule out a board larger than ``cols x rows`` in every
    one of ``images`` (with their ``detections``): each one's
    :func:`acs_cli.core.board_hint.extension_score` below
    :data:`acs_cli.core.board_hint.EXTENSION_SCREEN`, so no search is needed.

    The scores the detection measured are used; the images are read only where one is
    missing (a cache written before they were kept), and then returned for the search.
    """
    from acs_cli.core.board_hint import EXTENSION_SCREEN, extension_score

    scores = [d.extension if d.found else math.inf for d in detections]  # no board: search
    greys = None
    if any(s is None for s in scores):
        greys = read_images(images)
        scores = [
            extension_score(g, d.corners, cols, rows) if d.corners is not None else math.inf
            for g, d in zip(greys, detections, strict=True)
        ]
    return all(s is not None and s < EXTENSION_SCREEN for s in scores), greys


def few_boards(
    folder: Path,
    fd: FolderDetections,
    cols: int,
    rows: int,
    need: int,
    *,
    part_is_error: bool,
) -> str | None:
    """Check the board size against the images (a wrong ``--board`` is named, issue 13).

    - The given board is in fewer than ``need`` images, or in fewer than
      :data:`FEW_BOARDS` of them: when a nearby size is found where it was not,
      :class:`InputError` (exit 2) naming that size; else :class:`DegenerateMotionError`
      (exit 3) naming ``--board`` below ``need``, or a warning naming it.
    - The images where it was found show a larger board (OpenCV finds an 8x6 board inside a
      9x6 one, at a different place in each image): :class:`InputError` when
      ``part_is_error`` (poses: the board's frame would jump), else a warning (intrinsics:
      the part's geometry is still right). The images' pixels around the corners found are
      asked first (:func:`_larger_ruled_out`); the larger sizes are searched for only where
      they cannot rule it out.

    Returns
    -------
    str or None
        A warning, or None.
    """
    from acs_cli.core.board_hint import board_size_hint, larger_board_sizes

    images, found = fd.images, [d.found for d in fd.detections]
    k, n = int(sum(found)), len(images)
    if k >= need and k >= FEW_BOARDS * n:
        with_board = [i for i, f in enumerate(found) if f]
        tried = [with_board[i] for i in _spread(len(with_board))]
        ruled_out, greys = _larger_ruled_out(
            [images[i] for i in tried], [fd.detections[i] for i in tried], cols, rows
        )
        if ruled_out:
            return None
        if greys is None:
            greys = read_images([images[i] for i in tried])
        larger = board_size_hint(greys, larger_board_sizes(cols, rows))
        if larger is None or 2 * larger[1] < len(tried):
            return None
        (c, r), m = larger
        text = (
            f"the images show a {c}x{r} board (found in {m} of {len(tried)} images tried), "
            f"of which --board {cols}x{rows} is a part: give --board {c}x{r} (inner corners)"
        )
        if part_is_error:
            raise InputError(text + "; a part would put the board's origin at a different "
                             "corner in different images", path=folder)  # fmt: skip
        return text
    without = [p for p, f in zip(images, found, strict=True) if not f]
    advice, size = board_advice(without, cols, rows)
    if k == 0:
        raise no_board_error(folder, cols, rows, n, advice)
    if size is not None:
        raise InputError(
            f"a {cols}x{rows} board is in only {k} of {n} images; {advice}", path=folder
        )
    if k < need:
        raise DegenerateMotionError(
            f"a {cols}x{rows} board is in only {k} of {n} images, and {need} views are "
            f"needed; {advice}; else record more views at different distances and tilts"
        )
    return f"a {cols}x{rows} board is in only {k} of {n} images; {advice}"


#: Images :func:`no_target_error` looks at for markers of another family.
FAMILY_PROBES = 8
#: The target frame of each kind, as artifacts record it.
TARGET_FRAMES = {
    "aprilgrid": "Kalibr's: origin at tag 0's bottom-left corner, x right, y up (z out of "
    "the target)",
    "charuco": "OpenCV's: origin at the board's top-left corner, x right, y down, z into the board",
}


def target_views(
    detections: Sequence[Detection], target: MarkerTarget
) -> tuple[list[int], list[np.ndarray], list[np.ndarray]]:
    """The views of a target that determine a pose, with their own corners.

    Parameters
    ----------
    detections : sequence of Detection
        From :func:`detect_folder` with ``target``: corners ``(m, 2)``, NaN where unseen.
    target : AprilGrid or Charuco

    Returns
    -------
    views : list of int
        Indices of the detections whose seen corners pass
        :func:`acs_cli.core.targets.pose_ready`.
    object_points : list of ndarray, shape (k_i, 3)
        Each view's seen corners in the target frame, metres.
    image_points : list of ndarray, shape (k_i, 2)
        Their pixels.
    """
    pts = target.points()
    views: list[int] = []
    obj: list[np.ndarray] = []
    img: list[np.ndarray] = []
    for i, d in enumerate(detections):
        if not d.found or d.corners is None:
            continue
        c = np.asarray(d.corners, dtype=float)
        seen = np.all(np.isfinite(c), axis=1)
        if pose_ready(pts[seen]):
            views.append(i)
            obj.append(pts[seen])
            img.append(c[seen])
    return views, obj, img


def no_target_error(
    folder: Path, target: MarkerTarget, images: Sequence[ImageRef], seen: int = 0
) -> AcsError:
    """The error for a folder where no image shows enough of an AprilGrid or ChArUco.

    Looks at up to :data:`FAMILY_PROBES` images (spread over the folder) for markers of
    another family: when one shows them, an :class:`InputError` (exit 2) names the family;
    else a :class:`DegenerateMotionError` (exit 3) with advice. ``seen`` counts the images
    with some corners of the target, too few or too collinear for a pose.
    """
    n = len(images)
    probes = [images[int(i)] for i in np.unique(np.linspace(0, n - 1, min(n, FAMILY_PROBES)))]
    for p, img in zip(probes, read_images(probes), strict=True):
        family = find_other_family(img, target)
        if family is not None:
            return InputError(
                f"the images show markers of the {family} family, not the target's "
                f"{target.dictionary} (--target {target.short()}); check the target "
                "description (its dictionary or tag family)",
                path=ref_path(p) if isinstance(p, Path) else f"{ref_path(p)}: {p.name}",
            )
    few = f"; {seen} image(s) show fewer than {MIN_POSE_CORNERS} usable corners" if seen else ""
    return DegenerateMotionError(
        f"no {target.kind} ({target.short()}) found in any of {n} images{few}: record the "
        "target large, sharp and well lit (at least two whole tags or markers a view), and "
        "check --target",
        path=folder,
    )


def detect_folder(
    folder: Path,
    cols: int,
    rows: int,
    cache: Path,
    *,
    extra_caches: Sequence[Path] = (),
    workers: int | None = None,
    progress: Progress | None = None,
    target: MarkerTarget | None = None,
    selection: FrameSelection = EVERY_FRAME,
    topic: str | None = None,
) -> FolderDetections:
    """Detect the board in every image of a folder (or the kept frames of a video), reusing
    and updating a cache.

    Parameters
    ----------
    folder : Path
        The images (see :func:`acs_cli.io.images.list_images`), or a video file (see
        :mod:`acs_cli.io.video`).
    cols, rows : int
        Inner corners of the board.
    cache : Path
        The cache read and written (snapshots every :data:`CACHE_EVERY` detections, so an
        interrupted run resumes).
    extra_caches : sequence of Path
        More caches to read (e.g. the intrinsics stage's, from the poses stage).
    workers : int, optional
        Processes; default ``os.cpu_count()``. Few images run in this process.
    progress : callable, optional
        ``progress(done, total)`` after each image.
    target : AprilGrid or Charuco, optional
        Detect this target instead of the ``cols x rows`` board: each detection's corners
        are ``(m, 2)``, row ``j`` = corner id ``j``, NaN where unseen (``found``: any
        corner seen).
    selection : FrameSelection
        A video's frames to use (``--every``, ``--max-frames``); refused for a folder.
    topic : str, optional
        With a ROS bag (``folder``; see :mod:`acs_cli.io.bag`): its image topic.

    Boards whose squares are small in pixels escape OpenCV's quick check, which the detector
    relies on to fail fast on frames without a board. When the boards found have squares
    under :data:`FULL_SEARCH_SPACING_PX` (their smallest corner spacing, median over the
    boards), or no board is found, the frames that failed are searched again at full
    resolution (``detect_checkerboard(..., full_search=True)``, several hundred
    milliseconds a large frame): with no board found, first :data:`FULL_SEARCH_PROBE` of
    them spread over the input, the rest only if one of those shows a board. What it finds
    goes into the cache as the frame's detection.

    Returns
    -------
    FolderDetections

    Raises
    ------
    InputError
        No images, a corrupt image, or images of different sizes; a file that is not a
        video, or a video of which no frame decodes.
    """
    fd = _detect_each(
        folder, cols, rows, cache, extra_caches, workers, progress, target, selection, topic
    )
    if target is not None:
        return fd
    return _full_search_pass(fd, cols, rows, workers)


def _detect_each(
    folder: Path,
    cols: int,
    rows: int,
    cache: Path,
    extra_caches: Sequence[Path],
    workers: int | None,
    progress: Progress | None,
    target: MarkerTarget | None,
    selection: FrameSelection,
    topic: str | None,
) -> FolderDetections:
    """:func:`detect_folder`'s first pass: every image once, through the cache."""
    selection.check()
    if is_bag_path(folder) or topic is not None:
        if not is_bag_path(folder):
            raise InputError("--topic (topic) applies to ROS bags", path=folder)
        return _detect_video(
            folder, cols, rows, cache, extra_caches, workers, progress, target, selection,
            bag=True, topic=topic,
        )  # fmt: skip
    if is_video_path(folder):
        return _detect_video(
            folder, cols, rows, cache, extra_caches, workers, progress, target, selection
        )
    if not selection.trivial:
        raise InputError(
            "--every, --max-frames, --skip-blurred and --min-change (every, max_frames, "
            "skip_blurred, min_change) select frames of a video file; this is a folder of "
            "images",
            path=folder,
        )
    images = list_images(folder)
    known: dict[str, Detection] = {}
    for extra in extra_caches:
        known.update(read_detections(extra))
    own = read_detections(cache)
    known.update(own)
    total = len(images)
    # With nothing cached, every image is detected: the workers start at once and this
    # process hashes the images for their keys while they work (the hashes are remembered
    # for the artifact's header). Otherwise the keys come first, to find what is cached.
    early = not known and _pool_size(workers, total) > 1
    keys = [] if early else [_file_key(p, cols, rows, target) for p in images]
    found: dict[int, Detection] = {i: known[k] for i, k in enumerate(keys) if k in known}
    cached = len(found)
    todo = [i for i in range(total) if i not in found]
    done = cached
    if progress is not None:
        progress(done, total)

    store: dict[str, Detection] = dict(own)
    store.update({keys[i]: d for i, d in found.items()})
    dirty = bool(found) and set(store) != set(own)
    last_save = time.monotonic()

    def record(i: int, key: str, det: Detection) -> None:
        nonlocal done, dirty, last_save
        found[i] = det
        store[key] = det
        done += 1
        dirty = True
        if progress is not None:
            progress(done, total)
        if done % CACHE_EVERY == 0 or time.monotonic() - last_save > 2.0:
            write_detections(cache, store)
            dirty = False
            last_save = time.monotonic()

    n_workers = _pool_size(workers, len(todo))
    measure = total <= MEASURE_EXTENSION_UP_TO
    try:
        if n_workers <= 1:
            for i in todo:
                key, det, error = _detect_file(str(images[i]), cols, rows, target, measure)
                if error is not None:
                    raise InputError(error)
                if det is None:  # pragma: no cover - _detect_file's contract
                    raise RuntimeError("detection worker returned nothing")
                record(i, key, det)
        else:
            with _detection_pool(n_workers) as pool:
                pending: dict[Future[tuple[str, Detection | None, str | None]], int] = {
                    pool.submit(_detect_file, str(images[i]), cols, rows, target, measure): i
                    for i in todo
                }
                try:
                    if early:  # before any result: an unreadable file fails as it always did
                        keys = [_file_key(p, cols, rows, target) for p in images]
                    while pending:
                        ready, _ = wait(pending, return_when=FIRST_COMPLETED)
                        for fut in ready:
                            i = pending.pop(fut)
                            key, det, error = fut.result()
                            if error is not None:
                                raise InputError(error)
                            if det is None:  # pragma: no cover - _detect_file's contract
                                raise RuntimeError("detection worker returned nothing")
                            record(i, key, det)
                finally:
                    for fut in pending:
                        fut.cancel()
    finally:
        if dirty:
            write_detections(cache, store)

    dets = [found[i] for i in range(total)]
    return FolderDetections(images, dets, _common_size(images, dets), cached, cache, keys=keys)


#: Boards whose smallest corner spacing (median over the boards found, pixels) is under
#: this may have siblings the quick check missed: :func:`detect_folder` searches the frames
#: that failed at full resolution.
FULL_SEARCH_SPACING_PX = 20.0
#: With no board found at all, the full search tries this many failed frames (spread over
#: the input) before the rest.
FULL_SEARCH_PROBE = 8
#: Frames of a full search read (decoded) at a time: memory stays bounded.
FULL_SEARCH_CHUNK = 16
#: A frame's full search is cached under its key with this suffix (found or not), so that a
#: rerun does not search it again.
FULL_SEARCH_KEY = "+full"


def _detect_full(gray: np.ndarray, cols: int, rows: int) -> tuple[np.ndarray | None, float | None]:
    """Worker: ``detect_checkerboard`` with the full-resolution search; the corners and
    their larger-board screen score (:attr:`Detection.extension`)."""
    corners = detect_checkerboard(gray, cols, rows, full_search=True)
    return corners, _extension(gray, corners, cols, rows)


def _full_search(
    fd: FolderDetections, todo: Sequence[int], cols: int, rows: int, workers: int | None
) -> dict[int, Detection]:
    """The images ``todo`` of ``fd`` read again (a chunk at a time) and searched at full
    resolution; their new detections by index."""
    n_workers = min(_worker_count(workers), len(todo))
    out: dict[int, Detection] = {}
    pool = _detection_pool(n_workers) if n_workers > 1 else None
    try:
        for start in range(0, len(todo), FULL_SEARCH_CHUNK):
            chunk = list(todo[start : start + FULL_SEARCH_CHUNK])
            greys = read_images([fd.images[i] for i in chunk])
            args = (greys, [cols] * len(chunk), [rows] * len(chunk))
            got = pool.map(_detect_full, *args) if pool is not None else map(_detect_full, *args)
            for i, (corners, extension) in zip(chunk, got, strict=True):
                old = fd.detections[i]
                out[i] = Detection(
                    old.name, corners is not None, old.image_size, corners, extension
                )
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    return out


def _full_search_pass(
    fd: FolderDetections, cols: int, rows: int, workers: int | None
) -> FolderDetections:
    """:func:`detect_folder`'s second pass (its docstring): the failed frames searched at
    full resolution when the boards found are small, or none is; the cache updated."""
    failed = [i for i, d in enumerate(fd.detections) if not d.found]
    spacings = [
        corner_spacing_px(d.corners, cols, rows)
        for d in fd.detections
        if d.found and d.corners is not None
    ]
    if not failed or (spacings and float(np.median(spacings)) >= FULL_SEARCH_SPACING_PX):
        return fd
    store = read_detections(fd.cache) if fd.keys else {}
    full = {i: fd.keys[i] + FULL_SEARCH_KEY for i in failed} if fd.keys else {}
    got = {i: store[full[i]] for i in failed if full.get(i) in store}  # searched before

    def search(todo: Sequence[int]) -> None:
        new = [i for i in todo if i not in got]
        if new:
            got.update(_full_search(fd, new, cols, rows, workers))

    if not spacings:  # nothing found: a few probes before the whole input
        picks = np.unique(np.round(np.linspace(0, len(failed) - 1, FULL_SEARCH_PROBE)))
        search([failed[int(k)] for k in picks])
        if not any(d.found for d in got.values()):
            _cache_full_search(fd, store, full, got)
            return fd
    search(failed)
    _cache_full_search(fd, store, full, got)
    return dataclasses.replace(fd, detections=[got.get(i, d) for i, d in enumerate(fd.detections)])


def _cache_full_search(
    fd: FolderDetections,
    store: dict[str, Detection],
    full: dict[int, str],
    got: dict[int, Detection],
) -> None:
    """Each full search's result under its frame's full-search key, and a board it found
    under the frame's own key too (the detection the stages use)."""
    if not fd.keys:
        return
    new = {full[i]: d for i, d in got.items() if full[i] not in store}
    new.update({fd.keys[i]: d for i, d in got.items() if d.found})
    if new:
        store.update(new)
        write_detections(fd.cache, store)


def _common_size(images: Sequence[ImageRef], dets: Sequence[Detection]) -> tuple[int, int]:
    size = dets[0].image_size
    for p, d in zip(images, dets, strict=True):
        if d.image_size != size:
            raise InputError(
                f"image size {d.image_size[0]}x{d.image_size[1]} differs from "
                f"{size[0]}x{size[1]} of {images[0].name}: all images must come from one "
                "camera at one resolution",
                path=ref_path(p),
            )
    return size


#: Frames a video's detection keeps in flight per worker (memory stays bounded).
FRAMES_IN_FLIGHT = 2


def _detect_video(
    video: Path,
    cols: int,
    rows: int,
    cache: Path,
    extra_caches: Sequence[Path],
    workers: int | None,
    progress: Progress | None,
    target: MarkerTarget | None,
    selection: FrameSelection,
    *,
    bag: bool = False,
    topic: str | None = None,
) -> FolderDetections:
    """:func:`detect_folder` for a video (or a ROS bag's ``topic``): frames decoded one by
    one in this process and detected here or in a pool (at most :data:`FRAMES_IN_FLIGHT`
    per worker at a time).

    Cache keys are the video's SHA-256 (a bag's, with the topic) with the frame's index and
    presentation time."""
    known: dict[str, Detection] = {}
    for extra in extra_caches:
        known.update(read_detections(extra))
    own = read_detections(cache)
    known.update(own)
    sha = video_sha256(video) if not bag else f"{bag_key(video)}/{topic}"
    report = VideoRead()
    refs: list[VideoFrame] = []
    found: dict[int, Detection] = {}
    store: dict[str, Detection] = dict(own)
    cached = 0
    dirty = False
    last_save = time.monotonic()
    total = 0

    keys: dict[int, str] = {}

    def record(i: int, key: str, det: Detection, from_cache: bool) -> None:
        nonlocal dirty, last_save, cached
        found[i] = det
        keys[i] = key
        cached += from_cache
        if store.get(key) is not det:
            store[key] = det
            dirty = True
        if progress is not None:
            progress(len(found), max(total, len(refs)))
        if dirty and (len(found) % CACHE_EVERY == 0 or time.monotonic() - last_save > 2.0):
            write_detections(cache, store)
            dirty = False
            last_save = time.monotonic()

    def frame_key(ref: VideoFrame) -> str:
        return f"{sha}#{ref.index}@{ref.time_ns}"

    frames = (
        read_bag_frames(video, topic, selection, report)
        if bag
        else read_video_frames(video, selection, report)
    )
    first = next(frames)  # counts the frames first when max_frames is given
    if report.count is not None and selection.max_frames is not None:
        total = len(selection.indices(report.count) or ())
    elif report.estimate is not None:
        total = report.estimate
    n_workers = _worker_count(workers)

    def all_frames() -> Iterator[Any]:
        yield first
        yield from frames

    def check(result: tuple[str, Detection | None, str | None]) -> tuple[str, Detection]:
        key, det, error = result
        if error is not None:  # pragma: no cover - an array always detects
            raise InputError(error)
        if det is None:  # pragma: no cover - _detect_image's contract
            raise RuntimeError("detection worker returned nothing")
        return key, det

    pool: ProcessPoolExecutor | None = None
    uncached = 0
    pending: dict[Future[tuple[str, Detection | None, str | None]], int] = {}
    try:
        for frame in all_frames():
            ref = frame.ref
            i = len(refs)
            refs.append(ref)
            seed = frame_key(ref)
            key = (
                _target_key(seed, target)
                if target is not None
                else detection_key(seed, cols, rows, DETECTOR_VERSION)
            )
            if key in known:
                record(i, key, known[key], True)
                continue
            uncached += 1
            if n_workers <= 1 or uncached <= MIN_IMAGES_PER_WORKER:  # few: no pool
                result = _detect_image(frame.image, ref.name, seed, cols, rows, target)
                record(i, *check(result), False)
                continue
            if pool is None:
                pool = _detection_pool(n_workers)
            pending[pool.submit(_detect_image, frame.image, ref.name, seed, cols, rows, target)] = i
            while len(pending) >= FRAMES_IN_FLIGHT * n_workers:
                ready, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in ready:
                    record(pending.pop(fut), *check(fut.result()), False)
        for fut in list(pending):
            record(pending.pop(fut), *check(fut.result()), False)
    finally:
        for fut in pending:
            fut.cancel()
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        if dirty:
            write_detections(cache, store)
    if progress is not None:
        progress(len(found), len(refs))  # the estimated total, corrected
    dets = [found[i] for i in range(len(refs))]
    notes, frames_info = report.outcome(selection, len(refs))
    frames_info["times"] = (
        "header.stamp" if bag else "presentation timestamps (pts * time_base), seconds"
    )
    if bag:
        frames_info["topic"] = topic
    return FolderDetections(
        refs,
        dets,
        _common_size(refs, dets),
        cached,
        cache,
        times_ns=[r.time_ns for r in refs],
        notes=notes,
        frames=frames_info,
        keys=[keys[i] for i in range(len(refs))],
    )


def _check_config(config: IntrinsicsConfig) -> None:
    if config.cols < 2 or config.rows < 2:
        raise InputError(
            f"--board needs at least 2x2 inner corners, got {config.cols}x{config.rows}"
        )
    if config.cols == config.rows:
        pass  # square boards work; their ordering is fixed only up to 90-degree turns
    if not (np.isfinite(config.square) and config.square > 0):
        raise InputError(f"--square must be a positive length in metres, got {config.square}")
    if config.model not in MODELS:
        raise InputError(f"unknown --model {config.model!r}; use one of {', '.join(MODELS)}")
    for e in config.export:
        if e not in EXPORTS:
            raise InputError(f"unknown --export {e!r}; use one of {', '.join(EXPORTS)}")
    if "ros" in config.export:
        check_ros_camera_name(config.camera_name)


def run_intrinsics(
    images_dir: Path,
    output: Path,
    config: IntrinsicsConfig,
    progress: Progress | None = None,
) -> IntrinsicsRun:
    """Detect the board, calibrate the camera and write ``intrinsics.yaml`` atomically.

    Also writes ``<stem>.detections.npz`` (the detections cache) and the requested exports
    (``<stem>_camera_info.yaml`` for ROS, ``<stem>_opencv.yaml`` for OpenCV) beside it.

    Raises
    ------
    InputError
        Bad options, no or corrupt images, images of different sizes, no board anywhere,
        markers of another family than the target's.
    DegenerateMotionError
        Too few views of the board to calibrate, or no view of the target with enough
        corners (nothing but the cache is written).
    """
    _check_config(config)
    config.selection.check()
    inputs = input_files(images_dir)
    check_distinct_output(output, inputs)
    exports: dict[str, Path] = {}
    if "ros" in config.export:
        exports["ros"] = output.with_name(output.stem + "_camera_info.yaml")
    if "opencv" in config.export:
        exports["opencv"] = output.with_name(output.stem + "_opencv.yaml")
    for p in exports.values():
        check_distinct_output(p, [*inputs, output])
    for p in [output, cache_path_for(output), *exports.values()]:
        check_writable(p)  # before the detection, not after it
    cols, rows, target = config.cols, config.rows, config.target
    fd = detect_folder(
        images_dir,
        cols,
        rows,
        cache_path_for(output),
        workers=config.workers,
        progress=progress,
        target=target,
        selection=config.selection,
        topic=config.topic,
    )
    board_note = None
    if target is None:
        with_board = [i for i, d in enumerate(fd.detections) if d.found]
        board_note = few_boards(images_dir, fd, cols, rows, MIN_VIEWS, part_is_error=False)
        obj = board_points(cols, rows, config.square)
        img_pts = [np.asarray(fd.detections[i].corners) for i in with_board]
        obj_pts = [obj] * len(img_pts)
    else:
        with_board, obj_pts, img_pts = target_views(fd.detections, target)
        if not with_board:
            n_some = sum(d.found for d in fd.detections)
            raise no_target_error(images_dir, target, fd.images, n_some)
    skipped = [fd.images[i].name for i in range(len(fd.images)) if i not in set(with_board)]
    calib = calibrate_robust(obj_pts, img_pts, fd.image_size, config.model)
    names = [fd.images[i].name for i in with_board]
    used = [names[j] for j in calib.used]
    dropped = [
        DroppedView(names[j], float(calib.first_pass_per_view_rms[j])) for j in calib.dropped
    ]
    warnings: list[str] = [*fd.notes] + ([] if board_note is None else [board_note])
    if skipped:
        warnings.append(f"no board in {len(skipped)} image(s): {', '.join(skipped[:10])}")
    if dropped:
        warnings.append(
            f"{len(dropped)} view(s) dropped as outliers: "
            + ", ".join(f"{d.image} ({d.rms_px:.2f} px)" for d in dropped)
        )
    cov = intrinsics_covariance(calib, obj_pts, img_pts)
    degenerate = degenerate_distortion(config.model, calib.distortion, cov[4:, 4:])
    if degenerate:
        warnings.append(degenerate)

    dist_names = DISTORTION_NAMES[config.model]
    std = honest_std(calib, cov)
    verdict = judge(intrinsics_measures(calib.camera_matrix, calib.rms_px, std), config.accept_weak)
    repeats = len(calib.used) - calib.distinct
    if repeats >= max(3, len(calib.used) // 4):
        warnings.append(
            f"{len(calib.used)} views show the board from only {calib.distinct} distinct poses "
            f"({repeats} near-duplicates, a video?): repeats add little, and the stds count "
            "each pose once; move the board or the camera between images"
        )
    warnings += verdict.warnings()
    calibrator = "cv2.fisheye.calibrate" if config.model == "fisheye" else "calibrateCameraExtended"
    header = make_header(
        "intrinsics",
        {_input_role(fd): images_dir},
        method=f"OpenCV {calibrator} "
        f"({config.model} model) on {DETECTOR_VERSION} corners (coarse findChessboardCorners, "
        "cornerSubPix sized to the squares, X-junction fit); views with RMS above "
        "max(median + 3 * 1.4826 * MAD, 2 * median) dropped and the calibration redone",
        units={"square": "m", "camera_matrix": "px", "rms": "px", "distortion": "unitless"},
        frames={
            "camera_matrix": "pixels, OpenCV convention (centre of the top-left pixel at 0, 0)",
            "board": "origin at the first inner corner, x along a row, z into the board",
        },
    )
    if fd.frames is not None:
        header["video"] = fd.frames
    if target is not None:
        header["method"] = (
            f"OpenCV {calibrator} ({config.model} model) on the identified corners of a "
            f"{target.kind} ({TARGETS_DETECTOR_VERSION}: cv2.aruco markers, corners refined "
            f"as X-junctions), each view's own corners (at least {MIN_POSE_CORNERS}, not "
            "collinear); views with RMS above max(median + 3 * 1.4826 * MAD, 2 * median) "
            "dropped and the calibration redone"
        )
        header["frames"].pop("board", None)
        header["frames"]["target"] = TARGET_FRAMES[target.kind]
        header["units"].pop("square", None)
        header["units"]["target"] = "m"
    art = IntrinsicsArtifact(
        model=config.model,
        image_size=(int(fd.image_size[0]), int(fd.image_size[1])),
        camera_matrix=calib.camera_matrix,
        distortion=calib.distortion,
        distortion_names=list(dist_names),
        rms_px=calib.rms_px,
        per_view_rms_px={n: float(e) for n, e in zip(used, calib.per_view_rms, strict=True)},
        std=std if std else None,
        board=BoardSpec(cols, rows, config.square, "m") if target is None else None,
        target=None if target is None else target_to_mapping(target),
        images=ImagesUsed(
            total=len(fd.images),
            used=used,
            skipped_no_board=skipped,
            dropped_outliers=dropped,
        ),
        detector=DETECTOR_VERSION if target is None else TARGETS_DETECTOR_VERSION,
        detections_cache=fd.cache.name,
        exports={k: v.name for k, v in exports.items()},
        warnings=warnings,
        header=header,
        source=str(output),
        verdict=VerdictSection.from_verdict(verdict),
    )
    art.save(output)
    camera = (calib.camera_matrix, calib.distortion, fd.image_size, config.model)
    marks = weak_marks(output.name, art.verdict)
    if "ros" in exports:
        write_ros_camera_info(exports["ros"], *camera, config.camera_name, comments=marks)
    if "opencv" in exports:
        write_opencv_yaml(
            exports["opencv"],
            {**opencv_camera_values(*camera), "rms_px": calib.rms_px},
            comments=marks,
        )
    return IntrinsicsRun(calib, to_plain(art.to_doc()), output, exports, fd, warnings)
