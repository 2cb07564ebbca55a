"""Write image sequences as ROS bags (``rosbags``), for acscal's bag input.

A path ending in ``.bag`` is a ROS 1 bag; any other is a ROS 2 bag folder (SQLite ``.db3``,
or MCAP when ``mcap`` is true). Images are ``sensor_msgs/Image`` in ``mono8``, ``bgr8``,
``rgb8`` or ``mono16``, or ``sensor_msgs/CompressedImage`` (PNG) for ``encoding="png"``;
each message's ``header.stamp`` is the given time in integer nanoseconds.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["write_bag", "write_bag_topics"]


def _message(types: Any, img: NDArray[np.uint8], t_ns: int, encoding: str) -> Any:
    Time = types["builtin_interfaces/msg/Time"]
    Header = types["std_msgs/msg/Header"]
    header = Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9), frame_id="camera")
    if encoding == "png":
        ok, data = cv2.imencode(".png", img)
        if not ok:  # pragma: no cover - encoding a grey array does not fail
            raise ValueError("cannot encode a frame as PNG")
        msg = types["sensor_msgs/msg/CompressedImage"]
        return msg(header=header, format="png", data=data.ravel())
    h, w = img.shape[:2]
    if encoding in ("bgr8", "rgb8"):
        pix = np.repeat(img[:, :, None], 3, axis=2)
    elif encoding == "mono16":
        pix = img.astype("<u2") * 257
    else:
        pix = img
    data = np.ascontiguousarray(pix).view(np.uint8).ravel()
    return types["sensor_msgs/msg/Image"](
        header=header,
        height=h,
        width=w,
        encoding=encoding,
        is_bigendian=0,
        step=len(data) // h,
        data=data,
    )


def write_bag(
    path: str | Path,
    topic: str,
    frames: Iterable[NDArray[np.uint8]],
    times_ns: Sequence[int],
    encoding: str = "mono8",
    mcap: bool = False,
    extra_topics: Sequence[str] = (),
) -> Path:
    """Write greyscale frames to ``topic`` of a new bag.

    Parameters
    ----------
    path : str or Path
        ``*.bag`` (ROS 1) or a new folder (ROS 2).
    topic : str
    frames : iterable of ndarray, shape (h, w), uint8
    times_ns : sequence of int
        Each frame's ``header.stamp`` (and receive time), nanoseconds.
    encoding : {"mono8", "bgr8", "rgb8", "mono16", "png"}
    mcap : bool
        ROS 2: MCAP storage instead of SQLite.
    extra_topics : sequence of str
        ``std_msgs/String`` topics with one message each (not images).

    Returns
    -------
    Path
    """
    return write_bag_topics(
        path, {topic: (frames, times_ns)}, encoding, mcap=mcap, extra_topics=extra_topics
    )


def write_bag_topics(
    path: str | Path,
    topics: Mapping[str, tuple[Iterable[NDArray[np.uint8]], Sequence[int]]],
    encoding: str = "mono8",
    mcap: bool = False,
    extra_topics: Sequence[str] = (),
) -> Path:
    """:func:`write_bag` with several image topics: ``{topic: (frames, times_ns)}``."""
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = store.types
    kind = "sensor_msgs/msg/CompressedImage" if encoding == "png" else "sensor_msgs/msg/Image"
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    ros1 = p.suffix == ".bag"
    if ros1:
        from rosbags.rosbag1 import Writer as Writer1

        writer: Any = Writer1(p)
    else:
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        plugin = StoragePlugin.MCAP if mcap else StoragePlugin.SQLITE3
        writer = Writer2(p, version=8, storage_plugin=plugin)
    serialize = store.serialize_ros1 if ros1 else store.serialize_cdr
    first = 0
    with writer:
        for topic, (frames, times_ns) in topics.items():
            conn = writer.add_connection(topic, kind, typestore=store)
            first = int(times_ns[0])
            for img, t in zip(frames, times_ns, strict=False):
                msg = _message(types, img, int(t), encoding)
                writer.write(conn, int(t), serialize(msg, kind))
        for other in extra_topics:
            c = writer.add_connection(other, "std_msgs/msg/String", typestore=store)
            text = types["std_msgs/msg/String"](data="not an image")
            writer.write(c, first, serialize(text, "std_msgs/msg/String"))
    return p
