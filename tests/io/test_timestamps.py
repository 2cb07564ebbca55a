"""Image times (issue 11): file-name rules, nanoseconds kept digit for digit, timestamps
files, --fps, and TUM files that say when their times are frame numbers."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from acs_cli.core.pairing import pair_trajectories
from acs_cli.errors import InputError
from acs_cli.io.timestamps import image_times, read_timestamps_file, stamp_from_name
from acs_cli.io.trajectory import (
    Trajectory,
    read_trajectory,
    write_npz_poses,
    write_tum,
)

EUROC = ["1403636579763555584.png", "1403636579813555456.png", "1403636579863555584.png"]


def _poses(n: int) -> np.ndarray:
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, 0, 3] = np.arange(n, dtype=float)
    return T


@pytest.mark.parametrize(
    ("name", "unit", "ns"),
    [
        ("img_00012.png", "frame", 12),
        ("left01.jpg", "frame", 1),
        ("1403636579763555584.png", "nanoseconds", 1403636579763555584),
        ("cam0_1623456789123456.jpg", "microseconds", 1623456789123456000),
        ("IMG_1623456789123.jpg", "milliseconds", 1623456789123000000),
        ("frame_1623456789.png", "seconds", 1623456789000000000),
        ("frame_1623456789.123.png", "seconds", 1623456789123000000),
        ("t_0.5.png", "seconds", 500000000),
    ],
)
def test_name_rules(name: str, unit: str, ns: int) -> None:
    stamp = stamp_from_name(name)
    assert stamp is not None
    assert (stamp.unit, stamp.ns) == (unit, ns)


def test_a_name_without_a_number_has_no_stamp() -> None:
    assert stamp_from_name("board.png") is None


def test_nanosecond_names_keep_every_digit_through_npz_and_tum(tmp_path: Path) -> None:
    times = image_times(EUROC, EUROC)
    assert times.unit == "s" and times.has_timestamps and times.note is None
    assert times.nanoseconds is not None
    assert times.nanoseconds.tolist() == [int(Path(n).stem) for n in EUROC]
    assert times.seconds[1] - times.seconds[0] == pytest.approx(0.05, abs=1e-6)
    traj = Trajectory(
        times.seconds,
        _poses(3),
        source="x",
        format="npz",
        has_timestamps=True,
        timestamps_ns=times.nanoseconds,
    )
    write_npz_poses(tmp_path / "p.npz", traj)
    back = read_trajectory(tmp_path / "p.npz", "npz")
    assert back.timestamps_ns is not None
    assert back.timestamps_ns.tolist() == times.nanoseconds.tolist()
    write_tum(
        tmp_path / "p.tum", back.timestamps, back.T_world_cam, timestamps_ns=back.timestamps_ns
    )
    first = (tmp_path / "p.tum").read_text().splitlines()[1].split()[0]
    assert first == "1403636579.763555584"
    tum = read_trajectory(tmp_path / "p.tum", "tum")
    assert tum.timestamps_ns is not None
    assert tum.timestamps_ns.tolist() == times.nanoseconds.tolist()


@given(st.lists(st.integers(0, 2**62), min_size=1, max_size=20, unique=True))
def test_tum_round_trip_of_any_nanoseconds(values: list[int]) -> None:
    import tempfile

    ns = np.array(sorted(values), dtype=np.int64)
    seconds = ns // 10**9 + (ns % 10**9) / 1e9
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.tum"
        if np.any(np.diff(seconds) <= 0):
            return  # nanoseconds closer than a double resolves: not a valid trajectory
        write_tum(path, seconds, _poses(ns.size), timestamps_ns=ns)
        back = read_trajectory(path, "tum")
    assert back.timestamps_ns is not None
    assert back.timestamps_ns.tolist() == ns.tolist()


def test_frame_numbers_are_not_seconds_and_say_so(tmp_path: Path) -> None:
    names = [f"img_{i:05d}.png" for i in (10, 11, 13)]
    times = image_times(names, names)
    assert times.unit == "frame" and times.has_timestamps
    assert times.seconds.tolist() == [10.0, 11.0, 13.0]
    assert times.note is not None and "--fps" in times.note
    write_tum(tmp_path / "f.tum", times.seconds, _poses(3), note="times are frame numbers (x)")
    text = (tmp_path / "f.tum").read_text()
    assert text.splitlines()[1].startswith("# ") and "frame numbers" in text
    back = read_trajectory(tmp_path / "f.tum", "tum")
    assert back.timestamps.tolist() == [10.0, 11.0, 13.0] and back.time_unit == "frame"


def test_fps_turns_frame_numbers_into_seconds() -> None:
    names = [f"img_{i:05d}.png" for i in (10, 11, 13)]
    times = image_times(names, names, fps=30.0)
    assert times.unit == "s"
    np.testing.assert_allclose(times.seconds, [10 / 30, 11 / 30, 13 / 30], atol=1e-9)
    assert "30 frames per second" in times.source


def test_names_without_numbers_fall_back_to_the_folder_order() -> None:
    all_names = ["a.png", "b.png", "c.png", "d.png"]
    times = image_times(["b.png", "d.png"], all_names)
    assert (times.unit, times.has_timestamps) == ("frame", False)
    assert times.seconds.tolist() == [1.0, 3.0]
    with_fps = image_times(["b.png", "d.png"], all_names, fps=10.0)
    assert with_fps.has_timestamps and with_fps.seconds.tolist() == [0.1, 0.3]


def test_fps_with_names_that_carry_times_is_refused() -> None:
    with pytest.raises(InputError, match="drop --fps"):
        image_times(EUROC, EUROC, fps=20.0)


def test_timestamps_file_in_seconds_and_in_nanoseconds(tmp_path: Path) -> None:
    f = tmp_path / "times.csv"
    f.write_text("image,time\nimg_00001.png,0.100000001\nimg_00002.png,0.2\n")
    assert read_timestamps_file(f) == {"img_00001.png": 100000001, "img_00002.png": 200000000}
    euroc = tmp_path / "data.csv"
    euroc.write_text("#timestamp [ns],filename\n" + "".join(f"{Path(n).stem},{n}\n" for n in EUROC))
    stamps = read_timestamps_file(euroc)
    times = image_times(EUROC[:2], EUROC, timestamps=stamps)
    assert times.nanoseconds is not None
    assert times.nanoseconds.tolist() == [int(Path(n).stem) for n in EUROC[:2]]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("a.png,0.1,7\n", "expected an image name and a time"),
        ("a.png,0.1\na.png,0.2\n", "listed twice"),
        ("a.png,0.1\nb.png,soon\n", "not a time"),
        ("# nothing\n", "no entries"),
    ],
)
def test_bad_timestamps_files_name_the_problem(tmp_path: Path, text: str, match: str) -> None:
    f = tmp_path / "t.csv"
    f.write_text(text)
    with pytest.raises(InputError, match=match):
        read_timestamps_file(f)


def test_images_missing_from_the_timestamps_file_are_named() -> None:
    with pytest.raises(InputError, match=r"img_2\.png"):
        image_times(
            ["img_1.png", "img_2.png"], ["img_1.png", "img_2.png"], timestamps={"img_1.png": 1}
        )


def test_times_that_do_not_increase_are_refused() -> None:
    with pytest.raises(InputError, match="do not increase"):
        image_times(["a.png", "b.png"], ["a.png", "b.png"], timestamps={"a.png": 2, "b.png": 1})


def test_frame_numbers_do_not_pair_with_seconds() -> None:
    frames = Trajectory(np.arange(5.0), _poses(5), "f", "npz", True, time_unit="frame")
    seconds = Trajectory(np.arange(5.0), _poses(5), "s", "npz", True)
    with pytest.raises(InputError, match="frame numbers"):
        pair_trajectories(frames, seconds)
    assert pair_trajectories(frames, frames).n_pairs == 5


def test_decimal_names_without_fixed_decimals_sort_by_time(tmp_path: Path) -> None:
    from acs_cli.io.images import list_images

    stamps = ["1623456789", "1623456789.05", "1623456789.1", "1623456789.15", "1623456789.2"]
    for s in stamps[::-1]:
        (tmp_path / f"{s}.png").write_bytes(b"")
    names = [p.name for p in list_images(tmp_path)]
    assert names == [f"{s}.png" for s in stamps]
    times = image_times(names, names)
    np.testing.assert_allclose(times.seconds - 1623456789, [0, 0.05, 0.1, 0.15, 0.2], atol=1e-6)


def test_names_that_mix_units_or_go_back_are_refused_never_replaced() -> None:
    mixed = ["1403636579.5.png", "1403636580000000000.png", "1403636580.5.png"]
    for fps in (None, 10.0):
        with pytest.raises(InputError, match="mix time units"):
            image_times(mixed, mixed, fps=fps)
    back = ["t_2.5.png", "t_1.5.png"]
    with pytest.raises(InputError, match="do not increase"):
        image_times(back, back)


def test_times_beyond_int64_nanoseconds_are_refused(tmp_path: Path) -> None:
    huge = ["99999999999999999999.png", "99999999999999999999999.png"]
    with pytest.raises(InputError, match="out of range"):
        image_times(huge, huge)
    f = tmp_path / "t.csv"
    f.write_text("a.png,1e30\n")
    with pytest.raises(InputError, match="out of range"):
        read_timestamps_file(f)


@pytest.mark.parametrize(
    ("text", "ns"),
    [
        ("name,t_ns\na.png,123456789\n", 123456789),  # unit in the header
        ("name,t [ms]\na.png,1623456789123\n", 1623456789123 * 10**6),
        ("a.png,1623456789123\n", 1623456789123 * 10**6),  # 13 integer digits: milliseconds
        ('"a.png","1.5"\n', 1500000000),  # quoted fields
        ("name;time\r\na.png;2.25\r\n", 2250000000),  # semicolons, CRLF
    ],
)
def test_timestamps_file_units_and_dialects(tmp_path: Path, text: str, ns: int) -> None:
    f = tmp_path / "t.csv"
    f.write_bytes(text.encode())
    assert read_timestamps_file(f) == {"a.png": ns}


def test_a_bad_time_after_the_first_line_is_named(tmp_path: Path) -> None:
    f = tmp_path / "t.csv"
    f.write_text("a.png,0.1\nb.png,NaN\n")
    with pytest.raises(InputError, match="not a time") as err:
        read_timestamps_file(f)
    assert err.value.line == 2
