"""Write rendered image sequences as video files (PyAV), for acscal's video input.

``.mkv`` is FFV1 in 8-bit grey (lossless: the corners are those of the PNGs), ``.avi`` is
MJPEG (lossy, as many cameras record), ``.mp4`` is H.264 (``libx264``, lossy, yuv420p).
Each frame's presentation time is given in seconds (variable frame rate allowed) and kept
to the millisecond (the streams' time base is 1/1000 s).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Sequence
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["CODECS", "folder_to_video", "write_video"]

#: Codec and pixel format by suffix.
CODECS = {".mkv": ("ffv1", "gray"), ".avi": ("mjpeg", "yuvj420p"), ".mp4": ("libx264", "yuv420p")}
_TIME_BASE = Fraction(1, 1000)


def write_video(
    path: str | Path, frames: Iterable[NDArray[np.uint8]], times_s: Sequence[float]
) -> Path:
    """Encode greyscale frames into ``path`` (codec by suffix, see :data:`CODECS`).

    Parameters
    ----------
    path : str or Path
        ``.mkv``, ``.avi`` or ``.mp4``.
    frames : iterable of ndarray, shape (h, w), uint8
        One size for all.
    times_s : sequence of float
        Each frame's presentation time, seconds, increasing by at least 1 ms.

    Returns
    -------
    Path
    """
    import av

    p = Path(path)
    if p.suffix.lower() not in CODECS:
        raise ValueError(f"unknown video suffix {p.suffix!r}; use one of {', '.join(CODECS)}")
    codec, pix_fmt = CODECS[p.suffix.lower()]
    pts = [round(Fraction(t).limit_denominator(10**6) / _TIME_BASE) for t in times_s]
    if any(b <= a for a, b in itertools.pairwise(pts)):
        raise ValueError("frame times must increase by at least 1 ms")
    p.parent.mkdir(parents=True, exist_ok=True)
    rate = 10 if len(pts) < 2 else max(1, round(1000 * (len(pts) - 1) / (pts[-1] - pts[0])))
    with av.open(str(p), "w") as container:
        stream = container.add_stream(codec, rate=rate)
        stream.pix_fmt = pix_fmt
        stream.time_base = _TIME_BASE
        stream.codec_context.time_base = _TIME_BASE
        n = 0
        for img, t in zip(frames, pts, strict=False):
            if n == 0:
                stream.height, stream.width = img.shape[:2]
            frame = av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="gray")
            if pix_fmt != "gray":
                frame = frame.reformat(format=pix_fmt)
            frame.pts = t
            frame.time_base = _TIME_BASE
            for packet in stream.encode(frame):
                container.mux(packet)
            n += 1
        for packet in stream.encode():
            container.mux(packet)
    if n != len(pts):
        raise ValueError(f"{n} frames for {len(pts)} times")
    return p


def folder_to_video(
    folder: str | Path, path: str | Path, fps: float = 10.0, jitter: float = 0.0, seed: int = 0
) -> tuple[Path, list[float]]:
    """Encode a folder's PNG images (in name order) as a video.

    Parameters
    ----------
    folder : str or Path
    path : str or Path
        The video (see :func:`write_video`).
    fps : float
        Nominal frame rate.
    jitter : float
        Variable frame rate: each interval is ``1/fps`` times a factor drawn uniformly in
        ``[1 - jitter, 1 + jitter]`` (``0 <= jitter < 1``).
    seed : int

    Returns
    -------
    path : Path
    times : list of float
        The frames' presentation times, seconds (to the millisecond).
    """
    files = sorted(Path(folder).glob("*.png"))
    rng = np.random.default_rng(seed)
    steps = (1.0 + jitter * rng.uniform(-1, 1, max(len(files) - 1, 0))) / fps
    times = [round(float(t), 3) for t in np.concatenate([[0.0], np.cumsum(steps)])]
    images = (cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in files)
    return write_video(path, images, times), times


def panning_scene(
    n: int = 24, blurred: Sequence[int] = (5, 12), stopped: Sequence[int] = (8, 9, 10)
) -> tuple[list[NDArray[np.uint8]], set[int], set[int]]:
    """Frames of a camera panning over a blocky texture, for frame selection's rules.

    The camera moves 6 pixels a frame (320x480 views of an 800x480 texture), but not at the
    frames ``stopped`` (each the same view as the frame before), and the frames ``blurred``
    carry a horizontal pan's motion blur (a 15-pixel box).

    Returns
    -------
    frames : list of ndarray, shape (480, 320), uint8
    blurred, stopped : set of int
        The frames blurred, and those repeating the view before them.
    """
    rng = np.random.default_rng(7)
    texture = cv2.resize(
        rng.integers(0, 256, (24, 40), dtype=np.uint8), (800, 480), interpolation=cv2.INTER_NEAREST
    )
    frames, x = [], 0
    for i in range(n):
        x += 0 if i in stopped else 6
        view = np.ascontiguousarray(texture[:, x : x + 320])
        if i in blurred:
            view = np.asarray(cv2.blur(view, (15, 1)))
        frames.append(view)
    return frames, set(blurred), set(stopped)
