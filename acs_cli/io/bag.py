"""ROS bags as calibration frames: one image topic, read without a ROS installation.

Rules (``docs/formats.md``, "ROS bags"):

- a ROS 1 ``.bag`` file, a ROS 2 bag folder (``metadata.yaml`` with ``.db3`` or ``.mcap``
  files) is read with the ``rosbags`` package; ``--topic`` names the image topic;
- ``sensor_msgs/Image`` in ``mono8``, ``8UC1``, ``bgr8``, ``rgb8``, ``bgra8``, ``rgba8``,
  ``mono16``, ``16UC1`` (16-bit stretched to 0-255 per image, as 16-bit image files) and
  ``sensor_msgs/CompressedImage`` (JPEG, PNG) are taken, as 8-bit greyscale;
- a frame's time is its ``header.stamp``, integer nanoseconds (exact);
- frames are named by their index on the topic, from 0: ``frame_000123``; ``--every`` and
  ``--max-frames`` select among them as for videos (:class:`acs_cli.io.video.FrameSelection`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from acs_cli.errors import InputError
from acs_cli.io.atomic import file_sha256
from acs_cli.io.video import (
    EVERY_FRAME,
    DecodedFrame,
    FrameSelection,
    VideoFrame,
    VideoRead,
    ViewFilter,
    images_in_order,
)

__all__ = ["IMAGE_TYPES", "bag_key", "is_bag_path", "read_bag_frames", "read_bag_images"]

#: The message types read as images.
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
_COLOUR = {
    "bgr8": cv2.COLOR_BGR2GRAY,
    "rgb8": cv2.COLOR_RGB2GRAY,
    "bgra8": cv2.COLOR_BGRA2GRAY,
    "rgba8": cv2.COLOR_RGBA2GRAY,
}


def is_bag_path(path: str | Path) -> bool:
    """True for a ROS 1 ``.bag`` file, a ``.mcap`` file or a ROS 2 bag folder."""
    p = Path(path)
    if p.is_file():
        return p.suffix.lower() in (".bag", ".mcap")
    return p.is_dir() and (p / "metadata.yaml").is_file()


def bag_key(path: Path) -> str:
    """A content key of a bag for the detections cache: SHA-256 of its file(s)."""
    files = sorted(f for f in path.rglob("*") if f.is_file()) if path.is_dir() else [path]
    h = hashlib.sha256()
    for f in files:  # each file's name and content
        h.update(f.name.encode())
        h.update(file_sha256(f, "the bag").encode())
    return h.hexdigest()


def _reader(path: Path) -> Any:
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    try:
        reader = AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        reader.open()
    except Exception as exc:  # rosbags raises its own error types, and OSError
        text = " ".join(str(exc).split())[:160] or type(exc).__name__
        raise InputError(f"cannot read the ROS bag ({text})", path=path) from exc
    return reader


def _to_gray(msg: Any, msgtype: str, topic: str, path: Path) -> NDArray[np.uint8]:
    if msgtype.endswith("CompressedImage"):
        data = np.frombuffer(bytes(msg.data), np.uint8)
        img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
        if img is None:
            raise InputError(f"a CompressedImage on {topic} does not decode", path=path)
        if img.ndim == 3:
            img = cv2.cvtColor(
                img, cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
            )
        return _eight_bit(img)
    enc = str(msg.encoding).lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    raw = np.frombuffer(bytes(msg.data), np.uint8)
    if raw.size < h * step:
        raise InputError(f"an Image on {topic} holds fewer bytes than height * step", path=path)
    rows = raw[: h * step].reshape(h, step)
    if enc in ("mono8", "8uc1"):
        return np.ascontiguousarray(rows[:, :w])
    if enc in _COLOUR:
        ch = 4 if enc.endswith("a8") else 3
        return np.ascontiguousarray(cv2.cvtColor(rows[:, : w * ch].reshape(h, w, ch), _COLOUR[enc]))
    if enc in ("mono16", "16uc1"):
        dtype = ">u2" if msg.is_bigendian else "<u2"
        return _eight_bit(rows[:, : 2 * w].copy().view(dtype).reshape(h, w))
    raise InputError(
        f"topic {topic} has images in encoding {msg.encoding!r}, which acscal does not read "
        "(mono8, mono16, bgr8, rgb8, bgra8, rgba8, 16UC1, or CompressedImage)",
        path=path,
    )


def _eight_bit(img: np.ndarray) -> NDArray[np.uint8]:
    if img.dtype == np.uint8:
        return np.ascontiguousarray(img)
    f = img.astype(float)
    lo, hi = float(f.min()), float(f.max())
    scaled = (f - lo) * (255.0 / (hi - lo)) if hi > lo else np.zeros(f.shape)
    return np.clip(np.round(scaled), 0, 255).astype(np.uint8)


def read_bag_frames(
    path: str | Path,
    topic: str | None,
    selection: FrameSelection = EVERY_FRAME,
    report: VideoRead | None = None,
    only: Sequence[int] | None = None,
) -> Iterator[DecodedFrame]:
    """The images of one topic of a bag, one by one, as greyscale, keeping those selected.

    Frames are :class:`~acs_cli.io.video.DecodedFrame` whose reference names the bag
    (``video``), the topic, the index on the topic and ``header.stamp`` in nanoseconds.

    Raises
    ------
    InputError
        Not a bag, no ``topic`` given or not in the bag (the image topics are listed), a
        topic that is not an image, an unknown encoding, or no message on the topic.
    """
    p = Path(path)
    selection.check()
    rep = report if report is not None else VideoRead()
    reader = _reader(p)
    try:
        images = sorted({c.topic for c in reader.connections if c.msgtype in IMAGE_TYPES})
        listing = ", ".join(images) if images else "none"
        if not topic:
            raise InputError(f"a ROS bag needs --topic (its image topics: {listing})", path=p)
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise InputError(f"no topic {topic} in the bag (its image topics: {listing})", path=p)
        kinds = {c.msgtype for c in conns}
        if not kinds <= set(IMAGE_TYPES):
            raise InputError(
                f"topic {topic} holds {', '.join(sorted(kinds))}, not sensor_msgs/Image or "
                "sensor_msgs/CompressedImage",
                path=p,
            )
        count = sum(int(c.msgcount) for c in conns)
        wanted: set[int] | None = None
        if only is not None:
            wanted = {int(i) for i in only}
        elif selection.max_frames is not None:
            rep.count = count
            wanted = selection.indices(count)
        rep.estimate = -(-count // selection.every)
        view = ViewFilter(selection if only is None else EVERY_FRAME)
        last_ns: int | None = None
        repeated = 0
        for index, (conn, _t, raw) in enumerate(reader.messages(connections=conns)):
            rep.decoded = index + 1
            take = (index % selection.every == 0) if wanted is None else (index in wanted)
            if not take:
                continue
            msg = reader.deserialize(raw, conn.msgtype)
            t_ns = int(msg.header.stamp.sec) * 10**9 + int(msg.header.stamp.nanosec)
            if last_ns is not None and t_ns <= last_ns:
                repeated += 1
                continue
            image = _to_gray(msg, conn.msgtype, topic, p)
            if view.active and not rep.judged(view.judge(image)):
                continue
            last_ns = t_ns
            rep.kept += 1
            yield DecodedFrame(VideoFrame(p, index, t_ns, topic), image)
    finally:
        reader.close()
    if only is None and rep.kept == 0:
        raise InputError(f"no image on topic {topic}", path=p)
    rep.note_skipped(selection)
    if repeated:
        rep.notes.append(
            f"{repeated} image(s) skipped: their header.stamp does not increase past the "
            "previous kept image's"
        )


def read_bag_images(refs: Sequence[VideoFrame]) -> list[NDArray[np.uint8]]:
    """The pixels of some images of one bag's topic, in the order of ``refs`` (one pass)."""
    if not refs:
        return []
    frames = read_bag_frames(refs[0].video, refs[0].topic, only=[r.index for r in refs])
    return images_in_order(refs, frames, "read")
