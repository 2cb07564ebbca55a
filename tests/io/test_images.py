"""Image folders, image reading and the detections cache (round trip, key invalidation)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from acs_cli.core.checkerboard import DETECTOR_VERSION
from acs_cli.errors import InputError
from acs_cli.io.detections import (
    Detection,
    cache_path_for,
    detection_key,
    read_detections,
    write_detections,
)
from acs_cli.io.images import list_images, natural_key, read_gray
from acs_cli.stages.intrinsics import detect_folder


def board_image(cols: int = 9, rows: int = 6, square: int = 30, shift: int = 0) -> np.ndarray:
    """A fronto-parallel board of ``cols x rows`` inner corners on a 640x480 image."""
    img = np.full((480, 640), 255, np.uint8)
    x0, y0 = 120 + shift, 100
    for j in range(rows + 1):
        for i in range(cols + 1):
            if (i + j) % 2 == 0:
                y, x = y0 + j * square, x0 + i * square
                img[y : y + square, x : x + square] = 0
    return cv2.GaussianBlur(img, (0, 0), 0.8)


def test_natural_order_and_suffixes(tmp_path: Path) -> None:
    for name in ("img10.png", "img2.PNG", "img1.jpg", "notes.txt", "b.tif"):
        (tmp_path / name).write_bytes(b"x")
    assert [p.name for p in list_images(tmp_path)] == ["b.tif", "img1.jpg", "img2.PNG", "img10.png"]
    assert natural_key("a2") < natural_key("a10")


@pytest.mark.parametrize(
    ("setup", "message"),
    [("missing", "no such folder"), ("empty", "empty"), ("noimages", "no images")],
)
def test_list_images_errors(tmp_path: Path, setup: str, message: str) -> None:
    folder = tmp_path / "imgs"
    if setup != "missing":
        folder.mkdir()
    if setup == "noimages":
        (folder / "readme.txt").write_text("hi")
    with pytest.raises(InputError, match=message) as exc:
        list_images(folder)
    assert str(folder) in exc.value.one_line()


def test_read_gray_and_corrupt_files(tmp_path: Path) -> None:
    good = tmp_path / "good.png"
    cv2.imwrite(str(good), board_image())
    img, sha = read_gray(good)
    assert img.shape == (480, 640) and img.dtype == np.uint8 and len(sha) == 64
    junk = tmp_path / "x.png"
    junk.write_bytes(np.random.default_rng(0).integers(0, 256, 500, dtype=np.uint8).tobytes())
    with pytest.raises(InputError, match="corrupt"):
        read_gray(junk)
    ok, buf = cv2.imencode(".jpg", board_image())
    assert ok
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(buf.tobytes()[: len(buf) // 2])
    with pytest.raises(InputError, match="truncated JPEG"):
        read_gray(cut)
    empty = tmp_path / "e.png"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        read_gray(empty)


def test_bytes_after_the_image_are_not_truncation(tmp_path: Path) -> None:
    """Phones append trailers (or a whole video) after a JPEG's end marker, and tools write
    bytes after a PNG's IEND: the image is whole. A JPEG cut after its EXIF thumbnail, whose
    own end marker comes early, is still cut short."""
    img = board_image()
    ok, jpg = cv2.imencode(".jpg", img)
    ok2, png = cv2.imencode(".png", img)
    assert ok and ok2
    trailer = b"SEFH" + bytes(range(256)) * 40 + b"\xff\xd8\xff\xe0"
    for name, data in (("phone.jpg", jpg.tobytes()), ("tool.png", png.tobytes())):
        f = tmp_path / name
        f.write_bytes(data + trailer)
        np.testing.assert_array_equal(read_gray(f)[0], cv2.imdecode(data_u8(data), 0))
    ok, thumb = cv2.imencode(".jpg", img[::8, ::8])
    assert ok
    t = thumb.tobytes()
    app1 = b"Exif\x00\x00" + t  # a thumbnail inside an APP1 segment
    body = jpg.tobytes()
    exif = body[:2] + b"\xff\xe1" + (len(app1) + 2).to_bytes(2, "big") + app1 + body[2:]
    whole = tmp_path / "exif.jpg"
    whole.write_bytes(exif)
    assert read_gray(whole)[0].shape == (480, 640)
    cut = tmp_path / "exif_cut.jpg"
    cut.write_bytes(exif[: len(exif) - len(body) // 2])
    with pytest.raises(InputError, match="truncated JPEG"):
        read_gray(cut)


def data_u8(data: bytes) -> np.ndarray:
    return np.frombuffer(data, np.uint8)


def test_cache_round_trip(tmp_path: Path) -> None:
    corners = np.arange(108, dtype=float).reshape(54, 2) + 0.25
    dets = {
        "a:9x6:v": Detection("a.png", True, (640, 480), corners),
        "b:9x6:v": Detection("b.png", False, (640, 480), None),
        "c:4x3:v": Detection("c.png", True, (320, 240), corners[:12], 0.125),
        "d:4x3:v": Detection("d.png", True, (320, 240), corners[:12], float("inf")),
    }
    path = tmp_path / "out.detections.npz"
    write_detections(path, dets)
    back = read_detections(path)
    assert set(back) == set(dets)
    for k, d in dets.items():
        assert back[k].name == d.name and back[k].found == d.found
        assert back[k].image_size == d.image_size and back[k].extension == d.extension
        if d.corners is None:
            assert back[k].corners is None
        else:
            np.testing.assert_array_equal(back[k].corners, d.corners)
    assert cache_path_for(tmp_path / "cam" / "intrinsics.yaml").name == "intrinsics.detections.npz"


@pytest.mark.parametrize("found", [30, 22, 3])
def test_a_cache_is_compressed_where_it_is_mostly_padding(tmp_path: Path, found: int) -> None:
    """Whole boards are stored as they are (they hardly compress); a cache with a quarter or
    more of its corner coordinates NaN (boards not found) is compressed. Both read back."""
    import zipfile

    rng = np.random.default_rng(found)
    dets = {
        f"{i}:9x6:v": Detection(f"{i}.png", i < found, (640, 480), rng.normal(size=(54, 2)))
        if i < found
        else Detection(f"{i}.png", False, (640, 480), None)
        for i in range(30)
    }
    path = tmp_path / "c.detections.npz"
    write_detections(path, dets)
    with zipfile.ZipFile(path) as zf:
        kinds = {info.compress_type for info in zf.infolist()}
    assert kinds == ({zipfile.ZIP_DEFLATED} if 30 - found >= 30 / 4 else {zipfile.ZIP_STORED})
    back = read_detections(path)
    for k, d in dets.items():
        assert back[k].found == d.found
        if d.corners is not None:
            np.testing.assert_array_equal(back[k].corners, d.corners)


def test_a_cache_of_partly_seen_targets_is_compressed(tmp_path: Path) -> None:
    """A target's corners come whole, NaN where unseen: those NaN count too."""
    import zipfile

    corners = np.full((30, 80, 2), np.nan)
    corners[:, :20] = np.random.default_rng(1).normal(size=(30, 20, 2))
    dets = {
        f"{i}:aprilgrid/6x6#80:v": Detection(f"{i}.png", True, (640, 480), corners[i])
        for i in range(30)
    }
    path = tmp_path / "t.detections.npz"
    write_detections(path, dets)
    with zipfile.ZipFile(path) as zf:
        assert {info.compress_type for info in zf.infolist()} == {zipfile.ZIP_DEFLATED}
    back = read_detections(path)
    for k, d in dets.items():
        np.testing.assert_array_equal(back[k].corners, d.corners)


@pytest.mark.parametrize("cached", [False, True])
def test_an_image_this_process_cannot_hash_fails_before_any_detection_counts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, cached: bool
) -> None:
    """With nothing cached the workers start while this process hashes the images; a file it
    cannot read still ends the run with its own message, and no cache is written."""
    import acs_cli.io.atomic as atomic

    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(24):
        cv2.imwrite(str(folder / f"img{i}.png"), board_image(shift=i))
    cache = tmp_path / "c.detections.npz"
    if cached:  # a cache of another image: the keys come first
        write_detections(cache, {"x:9x6:v": Detection("x.png", False, (640, 480), None)})
    before = cache.read_bytes() if cached else None
    real = atomic.content_sha256

    def unreadable(path: str | Path) -> bytes:
        if Path(path).name == "img23.png":
            raise PermissionError(13, "Permission denied")
        return real(path)

    monkeypatch.setattr(atomic, "content_sha256", unreadable)
    with pytest.raises(InputError, match=r"cannot read image \(Permission denied\)"):
        detect_folder(folder, 9, 6, cache, workers=2)
    assert (cache.read_bytes() if cached else None) == before and cache.exists() == cached


def test_a_cache_without_the_screen_scores_reads_them_as_unmeasured(tmp_path: Path) -> None:
    """Caches written before ``extension`` was kept still read, their scores None."""
    corners = np.arange(108, dtype=float).reshape(54, 2)
    path = tmp_path / "old.detections.npz"
    write_detections(path, {"a:9x6:v": Detection("a.png", True, (640, 480), corners, 0.5)})
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k != "extension"}
    np.savez_compressed(path, **arrays)
    (back,) = read_detections(path).values()
    assert back.found and back.extension is None
    np.testing.assert_array_equal(back.corners, corners)


def test_the_larger_board_check_uses_the_scores_the_detection_measured(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A whole board's score is measured where the image is decoded for detection: the check
    for a larger board reads no image then; with a part of a board (8x6 of a 9x6), the score
    says so and the search names the whole board."""
    from acs_cli.core.board_hint import EXTENSION_SCREEN
    from acs_cli.stages import intrinsics as stage

    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(6):
        cv2.imwrite(str(folder / f"img{i}.png"), board_image(shift=8 * i))
    whole = detect_folder(folder, 9, 6, tmp_path / "w.npz", workers=1)
    assert all(d.extension is not None and d.extension < EXTENSION_SCREEN for d in whole.detections)
    read: list[int] = []
    real = stage.read_images
    monkeypatch.setattr(stage, "read_images", lambda refs: read.append(len(refs)) or real(refs))
    assert stage.few_boards(folder, whole, 9, 6, 3, part_is_error=False) is None
    assert read == []
    # the same detections without their scores (an older cache): the images are read
    old = [dataclasses.replace(d, extension=None) for d in whole.detections]
    assert stage.few_boards(folder, dataclasses.replace(whole, detections=old), 9, 6, 3,
                            part_is_error=False) is None  # fmt: skip
    assert read == [4]

    # a folder larger than MEASURE_EXTENSION_UP_TO: not measured (1.5 ms an image), read
    monkeypatch.setattr(stage, "MEASURE_EXTENSION_UP_TO", 5)
    large = detect_folder(folder, 9, 6, tmp_path / "l.npz", workers=1)
    assert all(d.found and d.extension is None for d in large.detections)
    assert stage.few_boards(folder, large, 9, 6, 3, part_is_error=False) is None
    assert read == [4, 4]
    monkeypatch.undo()

    part = detect_folder(folder, 8, 6, tmp_path / "p.npz", workers=1)
    assert all(d.found for d in part.detections)
    assert all(d.extension is not None and d.extension > EXTENSION_SCREEN for d in part.detections)
    note = stage.few_boards(folder, part, 8, 6, 3, part_is_error=False)
    assert note is not None and "9x6 board" in note


def test_bad_cache_reads_as_empty(tmp_path: Path) -> None:
    p = tmp_path / "c.npz"
    assert read_detections(p) == {}
    p.write_bytes(b"not an npz")
    assert read_detections(p) == {}


def test_detect_folder_reuses_cache_and_invalidates_on_change(tmp_path: Path) -> None:
    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"img{i}.png"), board_image(shift=10 * i))
    cv2.imwrite(str(folder / "img3.png"), np.full((480, 640), 90, np.uint8))
    cache = tmp_path / "out.detections.npz"
    first = detect_folder(folder, 9, 6, cache, workers=1)
    assert first.cached == 0 and cache.is_file()
    assert [d.found for d in first.detections] == [True, True, True, False]
    assert len(read_detections(cache)) == 4

    second = detect_folder(folder, 9, 6, cache, workers=1)
    assert second.cached == 4
    for a, b in zip(first.detections, second.detections, strict=True):
        assert a.found == b.found
        if a.corners is not None:
            np.testing.assert_array_equal(a.corners, b.corners)

    # change one image's content: its detection is redone, the others reused
    cv2.imwrite(str(folder / "img1.png"), board_image(shift=40))
    third = detect_folder(folder, 9, 6, cache, workers=1)
    assert third.cached == 3
    c1, c3 = third.detections[1].corners, first.detections[1].corners
    assert c1 is not None and c3 is not None
    assert np.abs(c1 - c3).max() > 20.0

    # another board size is another key
    fourth = detect_folder(folder, 8, 5, cache, workers=1)
    assert fourth.cached == 0 and not any(d.found for d in fourth.detections)
    sha = read_gray(folder / "img0.png")[1]
    keys = read_detections(cache)
    assert detection_key(sha, 9, 6, DETECTOR_VERSION) in keys
    assert detection_key(sha, 8, 5, DETECTOR_VERSION) in keys


def test_detect_folder_in_worker_processes(tmp_path: Path) -> None:
    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(26):
        cv2.imwrite(str(folder / f"f{i:03d}.png"), board_image(shift=i))
    seen: list[tuple[int, int]] = []
    res = detect_folder(
        folder, 9, 6, tmp_path / "c.npz", workers=2, progress=lambda d, t: seen.append((d, t))
    )
    assert all(d.found for d in res.detections)
    assert seen[-1] == (26, 26)
    serial = detect_folder(folder, 9, 6, tmp_path / "c2.npz", workers=1)
    for a, b in zip(res.detections, serial.detections, strict=True):
        np.testing.assert_allclose(a.corners, b.corners)


def test_detect_folder_errors(tmp_path: Path) -> None:
    folder = tmp_path / "imgs"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), board_image())
    cv2.imwrite(str(folder / "b.png"), cv2.resize(board_image(), (320, 240)))
    with pytest.raises(InputError, match="differs") as exc:
        detect_folder(folder, 9, 6, tmp_path / "c.npz", workers=1)
    assert "b.png" in exc.value.one_line()
    (folder / "b.png").unlink()
    (folder / "c.png").write_bytes(b"\x89PNG\r\n\x1a\nbroken")
    with pytest.raises(InputError, match=r"c\.png"):
        detect_folder(folder, 9, 6, tmp_path / "c.npz", workers=1)


def small_board_image(shift: int = 0) -> np.ndarray:
    """A 24x17 board of 12 px squares on a 1280x960 image: squares too small for OpenCV's
    quick board check."""
    img = np.full((960, 1280), 255, np.uint8)
    x0, y0, square = 300 + shift, 250, 12
    for j in range(18):
        for i in range(25):
            if (i + j) % 2 == 0:
                y, x = y0 + j * square, x0 + i * square
                img[y : y + square, x : x + square] = 0
    return cv2.GaussianBlur(img, (0, 0), 1.0)


def test_detect_folder_searches_the_failed_frames_again_when_boards_are_small(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Issue 21, item 6: boards of squares under about 16 px escape the quick check (the
    detector alone finds none here); the folder's failed frames are searched at full
    resolution, and what that finds is cached as the frames' detections."""
    from acs_cli.core.checkerboard import detect_checkerboard

    assert detect_checkerboard(small_board_image(), 24, 17) is None
    folder = tmp_path / "imgs"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"img{i}.png"), small_board_image(shift=7 * i))
    cv2.imwrite(str(folder / "img3.png"), np.full((960, 1280), 90, np.uint8))
    cache = tmp_path / "out.detections.npz"
    first = detect_folder(folder, 24, 17, cache, workers=1)
    assert [d.found for d in first.detections] == [True, True, True, False]
    c = first.detections[1].corners
    assert c is not None and abs(c[0, 0] - (300 + 7 + 12 - 0.5)) < 0.1  # the first corner
    import acs_cli.stages.intrinsics as stage

    searched: list[int] = []
    real = stage._full_search

    def spy(fd: Any, todo: Any, cols: int, rows: int, workers: Any) -> Any:
        searched.extend(todo)
        return real(fd, todo, cols, rows, workers)

    monkeypatch.setattr(stage, "_full_search", spy)
    second = detect_folder(folder, 24, 17, cache, workers=1)
    assert second.cached == 4 and searched == []  # the blank frame's search is cached too
    assert [d.found for d in second.detections] == [True, True, True, False]


def test_the_full_search_runs_only_for_small_boards_or_none(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Boards of ordinary squares: a failed frame is not searched again (it would cost
    hundreds of milliseconds a frame); no board anywhere: a few frames spread over the input
    are, and the rest only when one of them shows a board."""
    import acs_cli.stages.intrinsics as stage

    calls: list[list[int]] = []
    real = stage._full_search

    def spy(fd: Any, todo: Any, cols: int, rows: int, workers: Any) -> Any:
        calls.append(list(todo))
        return real(fd, todo, cols, rows, workers)

    monkeypatch.setattr(stage, "_full_search", spy)
    big = tmp_path / "big"
    big.mkdir()
    for i in range(3):
        cv2.imwrite(str(big / f"img{i}.png"), board_image(shift=10 * i))
    cv2.imwrite(str(big / "img3.png"), np.full((480, 640), 90, np.uint8))
    detect_folder(big, 9, 6, tmp_path / "big.npz", workers=1)
    assert calls == []
    blank = tmp_path / "blank"
    blank.mkdir()
    for i in range(12):
        cv2.imwrite(str(blank / f"img{i:02d}.png"), np.full((480, 640), 40 + 10 * i, np.uint8))
    got = detect_folder(blank, 9, 6, tmp_path / "blank.npz", workers=1)
    assert not any(d.found for d in got.detections)
    assert len(calls) == 1 and len(calls[0]) == stage.FULL_SEARCH_PROBE
    assert calls[0][0] == 0 and calls[0][-1] == 11
    # a rerun reads what the full search found (nothing) from the cache: no search
    detect_folder(blank, 9, 6, tmp_path / "blank.npz", workers=1)
    assert len(calls) == 1


def test_a_video_s_frames_go_through_the_pool_without_hanging(tmp_path: Path) -> None:
    """A video's first frames are detected in the process (OpenCV's threads started), the
    rest in a pool forked from it: the workers must start and find the same corners. (A
    worker that reconfigured OpenCV's threads hung on the fork's copy of their lock.) Run
    in a child process, so that a hang fails the test instead of the suite."""
    import subprocess
    import sys

    from sample_data_gen.video import write_video

    n = 30
    video = write_video(
        tmp_path / "board.mkv",
        [board_image(shift=3 * i) for i in range(n)],
        [0.1 * i for i in range(n)],
    )
    code = (
        "import sys\n"
        "from pathlib import Path\n"
        "from acs_cli.stages.intrinsics import detect_folder\n"
        "fd = detect_folder(Path(sys.argv[1]), 9, 6, Path(sys.argv[2]), workers=2)\n"
        "print(sum(d.found for d in fd.detections))\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code, str(video), str(tmp_path / "pool.npz")],
        capture_output=True, text=True, timeout=180,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert res.stdout.split()[-1] == str(n)
    pooled = read_detections(tmp_path / "pool.npz")
    serial = detect_folder(video, 9, 6, tmp_path / "serial.npz", workers=1)
    assert serial.cached == 0 and len(pooled) == n
    for k, d in zip(serial.keys, serial.detections, strict=True):
        assert d.corners is not None
        np.testing.assert_array_equal(pooled[k].corners, d.corners)
