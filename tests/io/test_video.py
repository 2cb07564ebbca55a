"""Video files written with sample_data_gen.video and read back with acs_cli.io.video."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acs_cli.errors import InputError
from acs_cli.io.video import (
    FrameSelection,
    VideoFrame,
    VideoRead,
    count_frames,
    frame_name,
    read_frame_images,
    read_video_frames,
    sharpness,
)
from sample_data_gen.video import panning_scene, write_video

TIMES = [0.0, 0.1, 0.25, 0.3, 0.42, 0.5, 0.61, 0.75, 0.8, 0.93]


def _frames(n: int = len(TIMES)) -> list[np.ndarray]:
    rng = np.random.default_rng(1)
    return [rng.integers(0, 256, (48, 64), dtype=np.uint8) for _ in range(n)]


@pytest.fixture(scope="module")
def mkv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_video(tmp_path_factory.mktemp("video") / "v.mkv", _frames(), TIMES)


def test_ffv1_frames_and_times_read_back_exactly(mkv: Path) -> None:
    report = VideoRead()
    got = list(read_video_frames(mkv, report=report))
    assert [f.ref.name for f in got] == [frame_name(i) for i in range(len(TIMES))]
    assert [f.ref.time_ns for f in got] == [round(t * 1e9) for t in TIMES]
    for f, want in zip(got, _frames(), strict=True):
        np.testing.assert_array_equal(f.image, want)
    assert (report.decoded, report.kept, report.notes) == (len(TIMES), len(TIMES), [])


@pytest.mark.parametrize("suffix", [".avi", ".mp4"])
def test_lossy_codecs_keep_the_times(tmp_path: Path, suffix: str) -> None:
    path = write_video(tmp_path / f"v{suffix}", _frames(), TIMES)
    got = list(read_video_frames(path))
    assert [f.ref.time_ns for f in got] == [round(t * 1e9) for t in TIMES]
    assert got[0].image.shape == (48, 64) and got[0].image.dtype == np.uint8


def test_every_and_max_frames(mkv: Path) -> None:
    every = [f.ref.index for f in read_video_frames(mkv, FrameSelection(every=3))]
    assert every == [0, 3, 6, 9]
    report = VideoRead()
    spread = [f.ref.index for f in read_video_frames(mkv, FrameSelection(2, 3), report)]
    assert spread == [0, 4, 8]  # of 0 2 4 6 8: first, middle, last
    assert report.count == len(TIMES) and report.kept == 3
    assert count_frames(mkv) == (len(TIMES), None)


def test_selection_rules() -> None:
    assert FrameSelection(1, 4).indices(100) == {0, 33, 66, 99}
    assert FrameSelection(10, 50).indices(100) == set(range(0, 100, 10))
    assert FrameSelection(5).indices(100) is None
    for bad in (FrameSelection(0), FrameSelection(1, 0)):
        with pytest.raises(InputError):
            bad.check()


def test_frames_read_again_by_index(mkv: Path) -> None:
    refs = [VideoFrame(mkv, 7, 0), VideoFrame(mkv, 2, 0)]
    imgs = read_frame_images(refs)
    np.testing.assert_array_equal(imgs[0], _frames()[7])
    np.testing.assert_array_equal(imgs[1], _frames()[2])


def test_truncated_video_gives_its_frames_and_a_note(mkv: Path, tmp_path: Path) -> None:
    data = mkv.read_bytes()
    cut = tmp_path / "cut.mkv"
    cut.write_bytes(data[: len(data) // 2])
    report = VideoRead()
    got = list(read_video_frames(cut, report=report))
    assert 0 < len(got) < len(TIMES)
    assert any("damaged" in n and "truncated" in n for n in report.notes)


def test_no_frame_or_not_a_video_is_an_input_error(mkv: Path, tmp_path: Path) -> None:
    head = tmp_path / "head.mkv"
    head.write_bytes(mkv.read_bytes()[:600])
    text = tmp_path / "notes.mp4"
    text.write_text("not a video\n" * 50)
    image = tmp_path / "img.png"
    image.write_bytes(b"\x89PNG\r\n\x1a\n")
    for path, words in ((head, "no frame"), (text, "not a folder of images, nor a video"),
                        (image, "image file")):  # fmt: skip
        with pytest.raises(InputError, match=words):
            list(read_video_frames(path))


def test_blurred_frames_and_repeated_views_are_skipped(tmp_path: Path) -> None:
    frames, blurred, repeated = panning_scene()
    assert sharpness(frames[5]) < 0.5 * sharpness(frames[4])
    video = write_video(tmp_path / "pan.mkv", frames, [0.04 * i for i in range(len(frames))])
    cases = [
        (FrameSelection(skip_blurred=True), blurred, (2, 0)),
        (FrameSelection(min_change=0.02), repeated, (0, 3)),
        (FrameSelection(skip_blurred=True, min_change=0.02), blurred | repeated, (2, 3)),
        (FrameSelection(every=2, skip_blurred=True), set(range(1, 24, 2)) | {12}, (1, 0)),
    ]
    for selection, skipped, counts in cases:
        report = VideoRead()
        kept = [f.ref.index for f in read_video_frames(video, selection, report)]
        assert kept == [i for i in range(len(frames)) if i not in skipped], selection
        assert (report.blurred, report.unchanged) == counts
        assert report.kept == len(kept) and report.decoded == len(frames)
        assert len(report.notes) == 1 and report.notes[0].startswith("frames skipped: ")
        assert not selection.trivial and "skipped" in selection.describe()
    # re-reading frames by index applies no rule
    assert [f.ref.index for f in read_video_frames(video, FrameSelection(), only=[5, 9])] == [5, 9]
    for bad in (0.0, 1.0, -0.1):
        with pytest.raises(InputError, match="--min-change"):
            FrameSelection(min_change=bad).check()
