"""Video files as calibration frames: decoded as they are used, with their own times.

Rules (``docs/formats.md``, "Video files"):

- any file FFmpeg decodes (``.mp4``, ``.mkv``, ``.mov``, ``.avi``; H.264, H.265, MJPEG, FFV1,
  ...) is read with PyAV; its first video stream is used;
- a frame's time is its presentation timestamp, ``pts * time_base`` seconds, kept as exact
  integer nanoseconds (variable frame rate included); a frame without one gets the previous
  frame's time plus one frame at the stream's average rate (and a note says so);
- frames are named by their index in the video, counting from 0: ``frame_000123``;
- selection: ``every=N`` keeps frames 0, N, 2N, ...; ``max_frames=M`` then keeps at most M of
  those, spread evenly over them (``round(linspace(0, K - 1, M))`` of the K left, which needs
  the frame count: a pass that reads the packets without decoding them);
- with ``skip_blurred``, a selected frame is skipped when its sharpness (the variance of the
  Laplacian of the frame scaled to at most ``THUMB_WIDTH`` pixels wide) is below
  ``BLUR_FRACTION`` of the median sharpness of the last ``BLUR_WINDOW`` selected frames, itself
  included (motion blur, focus hunting: relative to the recording around it, so that the
  rule does not depend on the scene's texture);
- with ``min_change``, a selected frame is skipped when it differs from the last kept frame
  by less than that share of the grey range (the mean absolute difference of the frames
  scaled to ``CHANGE_WIDTH`` pixels wide, over 255): a camera standing still gives the same
  view again;
- both rules run on the frames ``every`` and ``max_frames`` select, in that order, and are
  counted in the notes (so ``max_frames`` is then an upper bound);
- a frame whose time does not increase past the last kept frame's is skipped (noted);
- a damaged or truncated file gives the frames that decode and a note; no frame at all, or a
  file that is not a video, is an :class:`~acs_cli.errors.InputError`.

Nothing is written beside the input; memory holds one decoded frame at a time.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acs_cli.errors import InputError
from acs_cli.io.atomic import file_sha256
from acs_cli.io.images import IMAGE_SUFFIXES

__all__ = [
    "BLUR_FRACTION",
    "BLUR_WINDOW",
    "CHANGE_WIDTH",
    "EVERY_FRAME",
    "THUMB_WIDTH",
    "VIDEO_SUFFIXES",
    "DecodedFrame",
    "FrameSelection",
    "VideoFrame",
    "VideoRead",
    "ViewFilter",
    "count_frames",
    "estimate_frames",
    "frame_name",
    "images_in_order",
    "is_video_path",
    "read_frame_images",
    "read_video_frames",
    "sharpness",
    "video_sha256",
]

#: Suffixes (lower case) of common video files; any other *file* given where a folder of
#: images is expected is also tried as a video.
VIDEO_SUFFIXES = (".mp4", ".mkv", ".mov", ".avi", ".webm", ".m4v", ".mpg", ".mpeg", ".ts")
_NS = 10**9
#: Frames are judged for blur at most this wide (pixels): the same rule at any resolution.
THUMB_WIDTH = 640
#: A frame is blurred below this share of the recent frames' median sharpness ...
BLUR_FRACTION = 0.5
#: ... over this many selected frames (the frame itself included).
BLUR_WINDOW = 15
#: Frames are compared with the last kept one at this width (pixels).
CHANGE_WIDTH = 160


def frame_name(index: int) -> str:
    """The name of a video's frame in messages and artifacts: ``frame_000123``."""
    return f"frame_{index:06d}"


def is_video_path(path: str | Path) -> bool:
    """True for an existing file (not a folder): given where image folders are taken, it is
    read as a video."""
    return Path(path).is_file()


@dataclass(frozen=True)
class FrameSelection:
    """Which frames of a video are used.

    Attributes
    ----------
    every : int
        Keep every n-th frame (frames 0, n, 2n, ...).
    max_frames : int, optional
        Then keep at most this many, spread evenly over the recording.
    """

    every: int = 1
    max_frames: int | None = None
    #: skip frames blurred against the recording around them (module doc)
    skip_blurred: bool = False
    #: skip frames that differ from the last kept one by less than this share of the grey
    #: range (module doc); None: keep them
    min_change: float | None = None

    def check(self) -> None:
        """Raise :class:`InputError` for a non-positive ``every`` or ``max_frames``, or a
        ``min_change`` outside ``(0, 1)``."""
        if int(self.every) < 1:
            raise InputError(f"--every must be a positive number of frames, got {self.every}")
        if self.max_frames is not None and int(self.max_frames) < 1:
            raise InputError(f"--max-frames must be positive, got {self.max_frames}")
        if self.min_change is not None and not 0.0 < float(self.min_change) < 1.0:
            raise InputError(
                f"--min-change must be a share of the grey range between 0 and 1, got "
                f"{self.min_change}"
            )

    @property
    def trivial(self) -> bool:
        """True when every frame is kept."""
        return (
            self.every == 1
            and self.max_frames is None
            and not self.skip_blurred
            and self.min_change is None
        )

    def describe(self) -> str:
        """The rule in words."""
        parts = []
        if self.every > 1:
            parts.append(f"1 frame in {self.every}")
        if self.max_frames is not None:
            parts.append(f"at most {self.max_frames} frames spread evenly")
        if self.skip_blurred:
            parts.append(
                f"blurred ones skipped (sharpness below {BLUR_FRACTION:g} of the last "
                f"{BLUR_WINDOW} frames' median)"
            )
        if self.min_change is not None:
            parts.append(f"views changed by less than {100 * self.min_change:g}% skipped")
        return ", then ".join(parts) if parts else "every frame"

    def plain(self) -> dict[str, Any]:
        """The rule for an artifact's header."""
        return {
            "every": self.every,
            "max_frames": self.max_frames,
            "skip_blurred": self.skip_blurred,
            "min_change": self.min_change,
        }

    def indices(self, count: int) -> set[int] | None:
        """The frame indices kept from a video of ``count`` frames (None: every n-th,
        decided as frames come)."""
        if self.max_frames is None:
            return None
        candidates = np.arange(0, count, self.every)
        if len(candidates) <= self.max_frames:
            return {int(i) for i in candidates}
        pick = np.unique(np.round(np.linspace(0, len(candidates) - 1, self.max_frames)))
        return {int(candidates[int(k)]) for k in pick}


#: Every frame (no selection).
EVERY_FRAME = FrameSelection()


@dataclass(frozen=True)
class VideoFrame:
    """A reference to one frame of a video (its pixels are decoded again when needed).

    Attributes
    ----------
    video : Path
        The video file (or ROS bag).
    index : int
        The frame's index in the video (or on the bag's topic), from 0.
    time_ns : int
        Its presentation time (a bag's ``header.stamp``), integer nanoseconds.
    topic : str, optional
        A ROS bag's image topic (None for a video).
    """

    video: Path
    index: int
    time_ns: int
    topic: str | None = None

    @property
    def name(self) -> str:
        """``frame_000123``."""
        return frame_name(self.index)


@dataclass(frozen=True)
class DecodedFrame:
    """One decoded frame: its reference and its greyscale pixels."""

    ref: VideoFrame
    image: NDArray[np.uint8]


def sharpness(image: NDArray[np.uint8]) -> float:
    """The variance of the Laplacian of ``image`` scaled to :data:`THUMB_WIDTH`: higher for
    sharper frames of one scene."""
    import cv2

    from acs_cli.core.checkerboard import downscaled

    return float(cv2.Laplacian(downscaled(image, THUMB_WIDTH), cv2.CV_64F).var())


class ViewFilter:
    """The blur and change rules of a :class:`FrameSelection` (module doc), frame by frame.

    :meth:`judge` is given each selected frame in order and says why it is skipped (None:
    kept); it keeps what the rules need: the last ``BLUR_WINDOW`` sharpnesses and the last
    kept frame's thumbnail.
    """

    def __init__(self, selection: FrameSelection) -> None:
        self.selection = selection
        self.recent: list[float] = []
        self.last: NDArray[np.float32] | None = None

    @property
    def active(self) -> bool:
        return self.selection.skip_blurred or self.selection.min_change is not None

    def judge(self, image: NDArray[np.uint8]) -> str | None:
        """``"blurred"``, ``"unchanged"`` or None (kept)."""
        if self.selection.skip_blurred:
            s = sharpness(image)
            self.recent = [*self.recent[-(BLUR_WINDOW - 1) :], s]
            if s < BLUR_FRACTION * float(np.median(self.recent)):
                return "blurred"
        if self.selection.min_change is not None:
            from acs_cli.core.checkerboard import downscaled

            thumb = downscaled(image, CHANGE_WIDTH).astype(np.float32)
            if self.last is not None and self.last.shape == thumb.shape:
                change = float(np.mean(np.abs(thumb - self.last))) / 255.0
                if change < self.selection.min_change:
                    return "unchanged"
            self.last = thumb
        return None


@dataclass
class VideoRead:
    """What a pass over a video saw (filled in as its frames are decoded).

    Attributes
    ----------
    decoded : int
        Frames decoded.
    kept : int
        Frames handed out.
    count : int, optional
        Frames counted before decoding (with ``max_frames``), else None.
    estimate : int, optional
        Without ``max_frames``: the frames to be kept by the header's frame count, for a
        progress bar (None when unknown).
    notes : list of str
        Damage, frames without or with repeated times.
    """

    decoded: int = 0
    kept: int = 0
    count: int | None = None
    estimate: int | None = None
    notes: list[str] = field(default_factory=list)
    #: selected frames skipped by the blur and change rules (:class:`ViewFilter`)
    blurred: int = 0
    unchanged: int = 0

    def judged(self, verdict: str | None) -> bool:
        """Count a :meth:`ViewFilter.judge` verdict; True when the frame is kept."""
        if verdict == "blurred":
            self.blurred += 1
        elif verdict == "unchanged":
            self.unchanged += 1
        return verdict is None

    def outcome(self, selection: FrameSelection, kept: int) -> tuple[list[str], dict[str, Any]]:
        """The notes (the selection's line first, when there is one) and the artifact
        header's ``video`` counts of a pass that kept ``kept`` frames."""
        notes = list(self.notes)
        if not selection.trivial:
            notes.insert(0, f"video: used {kept} of {self.decoded} frames ({selection.describe()})")
        counts = {
            "decoded": self.decoded,
            "kept": kept,
            **selection.plain(),
            "skipped_blurred": self.blurred,
            "skipped_unchanged": self.unchanged,
        }
        return notes, counts

    def note_skipped(self, selection: FrameSelection) -> None:
        """Add the note that counts the frames the blur and change rules skipped."""
        parts = []
        if self.blurred:
            parts.append(
                f"{self.blurred} as blurred (sharpness below {BLUR_FRACTION:g} of the last "
                f"{BLUR_WINDOW} frames' median)"
            )
        if self.unchanged:
            parts.append(
                f"{self.unchanged} as too close to the last kept view (a change below "
                f"{100 * (selection.min_change or 0.0):g}% of the grey range)"
            )
        if parts:
            self.notes.append("frames skipped: " + "; ".join(parts))


def video_sha256(path: Path) -> str:
    """SHA-256 of a video file's bytes (:func:`acs_cli.io.atomic.file_sha256`)."""
    return file_sha256(path, "video")


def _ffmpeg_error() -> tuple[type[BaseException], ...]:
    import av

    return (av.FFmpegError, OSError, ValueError, EOFError)


def _open(path: Path) -> Any:
    """The container, opened; :class:`InputError` for a file that is not a video."""
    import av

    if not path.exists():
        raise InputError("no such file or folder", path=path)
    if path.suffix.lower() in IMAGE_SUFFIXES:
        raise InputError("is an image file: give the folder of images (or a video)", path=path)
    try:
        container = av.open(str(path), mode="r")
    except _ffmpeg_error() as exc:
        raise InputError(
            f"not a folder of images, nor a video FFmpeg can read ({_short(exc)})", path=path
        ) from exc
    if not container.streams.video:
        container.close()
        raise InputError("the file has no video stream", path=path)
    return container


def _short(exc: BaseException) -> str:
    text = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
    return " ".join(str(text).split())[:160]


def _ends_early(container: Any, first_ns: int | None, last_ns: int, n: int) -> str | None:
    """Why the frames decoded stop well before the duration the container declares (a
    truncated file whose header survived), or None."""
    duration = container.duration  # microseconds, or None
    if duration is None or first_ns is None or n < 2:
        return None
    step = (last_ns - first_ns) / (n - 1)
    end = first_ns + int(duration) * 1000
    if end - last_ns > 2.5 * step + 1e6:
        return (
            f"truncated: the frames stop at {last_ns / _NS:.3f} s of the "
            f"{int(duration) / 1e6:.3f} s the file declares"
        )
    return None


def estimate_frames(path: Path) -> int | None:
    """The frame count a video's header declares (or its duration times its average rate),
    for a progress bar; None when it says neither."""
    container = _open(path)
    try:
        stream = container.streams.video[0]
        if stream.frames:
            return int(stream.frames)
        rate = stream.average_rate
        if container.duration and rate:
            return round(container.duration / 1e6 * float(rate))
        return None
    finally:
        container.close()


def count_frames(path: Path) -> tuple[int, str | None]:
    """The number of frames of a video's first video stream, by reading its packets
    without decoding them; with a note when the file ends in damage."""
    container = _open(path)
    n, note = 0, None
    try:
        stream = container.streams.video[0]
        try:
            for packet in container.demux(stream):
                if packet.size:
                    n += 1
        except _ffmpeg_error() as exc:
            note = f"the video is damaged after {n} frames ({_short(exc)})"
    finally:
        container.close()
    return n, note


def read_video_frames(
    path: str | Path,
    selection: FrameSelection = EVERY_FRAME,
    report: VideoRead | None = None,
    only: Sequence[int] | None = None,
) -> Iterator[DecodedFrame]:
    """Decode a video's frames one by one, as greyscale, keeping those selected.

    Parameters
    ----------
    path : str or Path
        A video file.
    selection : FrameSelection
        Which frames to hand out (see the module's rules).
    report : VideoRead, optional
        Filled in with counts and notes as the frames are decoded.
    only : sequence of int, optional
        Hand out just these frame indices (overrides ``selection``); decoding stops after
        the last.

    Yields
    ------
    DecodedFrame

    Raises
    ------
    InputError
        Not a video, or no frame decodes (raised when the pass ends).
    """
    p = Path(path)
    selection.check()
    rep = report if report is not None else VideoRead()
    wanted: set[int] | None
    if only is not None:
        wanted = {int(i) for i in only}
    else:
        wanted = None
        if selection.max_frames is not None:
            rep.count, note = count_frames(p)
            if note is not None:
                rep.notes.append(note)
            wanted = selection.indices(rep.count)
    if report is not None and rep.count is None and only is None:
        guess = estimate_frames(p)
        rep.estimate = None if guess is None else -(-guess // selection.every)
    last_wanted = max(wanted) if wanted else None
    view = ViewFilter(selection if only is None else EVERY_FRAME)
    container = _open(p)
    errors = _ffmpeg_error()
    try:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        rate = stream.average_rate or stream.guessed_rate
        step_ns = round(_NS / Fraction(rate)) if rate else None
        index = 0
        last_ns: int | None = None
        first_ns: int | None = None
        kept_ns: int | None = None
        no_pts = repeated = bad_packets = 0
        first_error: str | None = None
        packets = container.demux(stream)
        while True:
            try:
                packet = next(packets)
            except StopIteration:
                break
            except errors as exc:  # truncated container
                first_error = first_error or _short(exc)
                bad_packets += 1
                break
            try:
                frames = packet.decode()
            except errors as exc:
                first_error = first_error or _short(exc)
                bad_packets += 1
                continue
            for frame in frames:
                if frame.pts is not None and frame.time_base is not None:
                    t_ns = round(Fraction(frame.pts) * Fraction(frame.time_base) * _NS)
                elif last_ns is not None and step_ns is not None:
                    t_ns = last_ns + step_ns
                    no_pts += 1
                else:
                    t_ns = 0 if step_ns is None else index * step_ns
                    no_pts += 1
                i = index
                index += 1
                first_ns = t_ns if first_ns is None else first_ns
                last_ns = t_ns
                rep.decoded = index
                take = (i % selection.every == 0) if wanted is None else (i in wanted)
                if not take:
                    continue
                if kept_ns is not None and t_ns <= kept_ns:
                    repeated += 1
                    continue
                image = np.ascontiguousarray(frame.to_ndarray(format="gray"))
                if view.active and not rep.judged(view.judge(image)):
                    continue
                kept_ns = t_ns
                rep.kept += 1
                yield DecodedFrame(VideoFrame(p, i, t_ns), image)
            if last_wanted is not None and only is not None and index > last_wanted:
                break
        if only is None and first_error is None and last_ns is not None:
            first_error = _ends_early(container, first_ns, last_ns, index)
            bad_packets += first_error is not None
    finally:
        container.close()
    if only is None and rep.kept == 0:
        why = f" ({first_error})" if first_error else ""
        raise InputError(f"no frame of the video decodes{why}", path=p)
    rep.note_skipped(selection)
    if bad_packets:
        rep.notes.append(
            f"the video is damaged ({first_error}): used the {rep.decoded} frames that decode"
        )
    if no_pts:
        rep.notes.append(
            f"{no_pts} frame(s) have no presentation timestamp: timed one frame after the "
            "previous at the stream's average rate"
        )
    if repeated:
        rep.notes.append(
            f"{repeated} frame(s) skipped: their presentation time does not increase past "
            "the previous kept frame's"
        )


def read_frame_images(refs: Sequence[VideoFrame]) -> list[NDArray[np.uint8]]:
    """The pixels of some frames of one video, in the order of ``refs`` (one decoding pass)."""
    if not refs:
        return []
    frames = read_video_frames(refs[0].video, only=[r.index for r in refs])
    return images_in_order(refs, frames, "decode")


def images_in_order(
    refs: Sequence[VideoFrame], frames: Iterable[DecodedFrame], verb: str
) -> list[NDArray[np.uint8]]:
    """The pixels of ``frames`` (one pass over ``refs``' input) in the order of ``refs``
    (non-empty); a frame the pass did not give again is an ``InputError`` ("cannot
    ``verb`` frame_000012 again")."""
    by_index = {f.ref.index: f.image for f in frames}
    missing = [r.name for r in refs if r.index not in by_index]
    if missing:
        raise InputError(f"cannot {verb} {', '.join(missing)} again", path=refs[0].video)
    return [by_index[r.index] for r in refs]
