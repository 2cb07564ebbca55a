"""ROS bags written with sample_data_gen.bag and read back with acs_cli.io.bag."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acs_cli.errors import InputError
from acs_cli.io.bag import is_bag_path, read_bag_frames, read_bag_images
from acs_cli.io.video import FrameSelection, VideoFrame, VideoRead
from sample_data_gen.bag import write_bag
from sample_data_gen.video import panning_scene

TOPIC = "/cam/image_raw"
#: header.stamp values a float of seconds would round: exact to the nanosecond
TIMES = [1_700_000_000_000_000_001 + k * 33_333_333 for k in range(6)]


def _frames() -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    return [rng.integers(0, 256, (24, 32), dtype=np.uint8) for _ in TIMES]


@pytest.mark.parametrize(
    ("name", "mcap"), [("r1.bag", False), ("r2_sqlite", False), ("r2_mcap", True)]
)
def test_every_bag_kind_reads_back_exactly(tmp_path: Path, name: str, mcap: bool) -> None:
    bag = write_bag(tmp_path / name, TOPIC, _frames(), TIMES, mcap=mcap)
    assert is_bag_path(bag)
    got = list(read_bag_frames(bag, TOPIC))
    assert [f.ref.time_ns for f in got] == TIMES
    assert [f.ref.name for f in got] == [f"frame_{i:06d}" for i in range(len(TIMES))]
    for f, want in zip(got, _frames(), strict=True):
        np.testing.assert_array_equal(f.image, want)


@pytest.mark.parametrize("encoding", ["bgr8", "rgb8", "png", "mono16"])
def test_encodings_become_the_same_grey(tmp_path: Path, encoding: str) -> None:
    bag = write_bag(tmp_path / "e.bag", TOPIC, _frames(), TIMES, encoding=encoding)
    got = [f.image for f in read_bag_frames(bag, TOPIC)]
    for img, want in zip(got, _frames(), strict=True):
        if encoding == "mono16":  # stretched to 0-255 per image, as 16-bit image files
            lo, hi = float(want.min()), float(want.max())
            want = np.round((want - lo) * 255.0 / (hi - lo)).astype(np.uint8)
        np.testing.assert_array_equal(img, want)


def test_selection_and_frames_read_again(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "s.bag", TOPIC, _frames(), TIMES)
    report = VideoRead()
    kept = list(read_bag_frames(bag, TOPIC, FrameSelection(2, 2), report))
    assert [f.ref.index for f in kept] == [0, 4] and report.count == len(TIMES)
    again = read_bag_images([VideoFrame(bag, 3, 0, TOPIC)])
    np.testing.assert_array_equal(again[0], _frames()[3])


@pytest.mark.parametrize(
    ("topic", "says"),
    [
        (None, f"needs --topic (its image topics: {TOPIC})"),
        ("/nope", f"no topic /nope in the bag (its image topics: {TOPIC})"),
        ("/chatter", "topic /chatter holds std_msgs/msg/String, not sensor_msgs/Image"),
    ],
)
def test_a_wrong_topic_is_named(tmp_path: Path, topic: str | None, says: str) -> None:
    bag = write_bag(tmp_path / "t.bag", TOPIC, _frames(), TIMES, extra_topics=["/chatter"])
    with pytest.raises(InputError, match=r"\(|topic") as info:
        list(read_bag_frames(bag, topic))
    assert says in info.value.message


def test_an_unknown_encoding_is_named(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "u.bag", TOPIC, _frames(), TIMES, encoding="bayer_rggb8")
    with pytest.raises(InputError, match="encoding 'bayer_rggb8'"):
        list(read_bag_frames(bag, TOPIC))


def test_not_a_bag_is_an_input_error(tmp_path: Path) -> None:
    fake = tmp_path / "x.bag"
    fake.write_text("not a bag\n")
    with pytest.raises(InputError, match="cannot read the ROS bag"):
        list(read_bag_frames(fake, TOPIC))


def test_blurred_and_repeated_images_of_a_topic_are_skipped(tmp_path: Path) -> None:
    frames, blurred, repeated = panning_scene()
    times = [TIMES[0] + k * 33_333_333 for k in range(len(frames))]
    bag = write_bag(tmp_path / "pan.bag", TOPIC, frames, times)
    report = VideoRead()
    selection = FrameSelection(skip_blurred=True, min_change=0.02)
    kept = [f.ref.index for f in read_bag_frames(bag, TOPIC, selection, report)]
    assert kept == [i for i in range(len(frames)) if i not in blurred | repeated]
    assert (report.blurred, report.unchanged) == (2, 3) and report.notes[0].startswith("frames")
