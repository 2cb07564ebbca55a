"""``acscal intrinsics`` and ``acscal poses`` on video files (issue 21), end to end."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import read_trajectory
from sample_data_gen.render import render_scenario
from sample_data_gen.video import folder_to_video, write_video

FRAMES = 16


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """One rendered camera as a PNG folder and as an FFV1 video at a variable frame rate,
    with the folder's calibration for comparison."""
    d = tmp_path_factory.mktemp("video")
    scene = render_scenario(
        d / "render", "fixed_joint", seed=3, frames=FRAMES, size=(320, 240), board_distance=0.45
    )
    folder = scene / "cam_a"
    video, times = folder_to_video(folder, d / "in" / "cam_a.mkv", fps=10, jitter=0.3, seed=2)
    intr_folder = d / "folder" / "intrinsics.yaml"
    res = acscal("intrinsics", folder, "--board", "9x6", "-o", intr_folder)
    assert res.returncode == 0, res.stderr
    return {"dir": d, "folder": folder, "video": video, "times": times, "intr": intr_folder}


def test_intrinsics_from_a_video_match_its_frames(recording: dict, tmp_path: Path) -> None:
    video: Path = recording["video"]
    before = sorted(video.parent.iterdir())
    out = tmp_path / "intrinsics.yaml"
    res = acscal("intrinsics", video, "--board", "9x6", "-o", out)
    assert res.returncode == 0, res.stderr
    doc = yaml.safe_load(out.read_text())
    ref = yaml.safe_load(Path(recording["intr"]).read_text())
    np.testing.assert_allclose(doc["camera_matrix"], ref["camera_matrix"], rtol=1e-9)
    assert doc["images"]["total"] == FRAMES
    assert all(n.startswith("frame_0000") for n in doc["images"]["used"])
    assert doc["inputs"]["video"]["path"].endswith("cam_a.mkv")
    assert doc["video"]["decoded"] == FRAMES and doc["video"]["kept"] == FRAMES
    assert sorted(video.parent.iterdir()) == before  # nothing written beside the input
    again = acscal("intrinsics", video, "--board", "9x6", "-o", out, "--json")
    assert again.returncode == 0, again.stderr
    assert f"{FRAMES} detections from the cache" in again.stderr + again.stdout


def test_poses_take_the_presentation_times(recording: dict, tmp_path: Path) -> None:
    npz, tum = tmp_path / "poses.npz", tmp_path / "poses.txt"
    res = acscal(
        "poses", recording["video"], "--intrinsics", recording["intr"], "-o", npz, "--tum", tum
    )
    assert res.returncode == 0, res.stderr
    art = PosesArtifact.load(npz)
    names = art.trajectory.names
    assert names is not None and all(n.startswith("frame_") for n in names)
    want = {f"frame_{i:06d}": t for i, t in enumerate(recording["times"])}
    np.testing.assert_array_equal(
        art.trajectory.timestamps_ns, [round(want[n] * 1e9) for n in names]
    )
    assert "presentation timestamps" in art.header["timestamps_from"]
    traj = read_trajectory(tum)
    np.testing.assert_allclose(traj.timestamps, [want[n] for n in names], atol=1e-9)


def test_max_frames_and_every_are_reported(recording: dict, tmp_path: Path) -> None:
    npz = tmp_path / "poses.npz"
    res = acscal(
        "poses", recording["video"], "--intrinsics", recording["intr"], "-o", npz,
        "--every", "2", "--max-frames", "4",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "used 4 of 16 frames (1 frame in 2, then at most 4 frames spread evenly)" in res.stderr
    art = PosesArtifact.load(npz)
    kept = {"frame_000000", "frame_000004", "frame_000010", "frame_000014"}
    assert art.trajectory.names is not None and set(art.trajectory.names) <= kept
    assert art.header["video"]["max_frames"] == 4 and art.header["video"]["every"] == 2


def test_blurred_frames_and_repeated_views_are_skipped_and_counted(
    recording: dict, tmp_path: Path
) -> None:
    """The camera stops after frame 6 (two repeats of its view) and frame 10 is smeared by a
    fast pan: --min-change drops the repeats, --skip-blurred the smeared frame."""
    frames = [
        cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted(recording["folder"].glob("*.png"))
    ]
    frames[10] = cv2.blur(frames[10], (41, 1))
    frames = [*frames[:7], frames[6], frames[6], *frames[7:]]  # frames 7 and 8 repeat 6
    video = write_video(tmp_path / "stop.mkv", frames, [0.1 * i for i in range(len(frames))])
    npz = tmp_path / "poses.npz"
    res = acscal(
        "poses", video, "--intrinsics", recording["intr"], "-o", npz,
        "--min-change", "0.05", "--skip-blurred",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    info = PosesArtifact.load(npz).header["video"]
    assert info["skipped_unchanged"] == 2 and info["skipped_blurred"] >= 1
    assert info["skip_blurred"] is True and info["min_change"] == 0.05
    assert info["kept"] + info["skipped_unchanged"] + info["skipped_blurred"] == len(frames)
    assert f"{info['skipped_blurred']} as blurred" in res.stderr
    assert "2 as too close to the last kept view" in res.stderr
    names = set(PosesArtifact.load(npz).trajectory.names or [])
    assert not names & {"frame_000007", "frame_000008", "frame_000012"}  # 12: smeared 10
    folder = acscal(
        "poses", recording["folder"], "--intrinsics", recording["intr"], "-o", tmp_path / "f.npz",
        "--skip-blurred",
    )  # fmt: skip
    assert folder.returncode == 2 and "select frames of a video file" in folder.stderr


def test_truncated_video_warns_and_uses_what_decodes(recording: dict, tmp_path: Path) -> None:
    data = Path(recording["video"]).read_bytes()
    cut = tmp_path / "cut.mkv"
    cut.write_bytes(data[: len(data) * 2 // 3])
    out = tmp_path / "intrinsics.yaml"
    res = acscal("intrinsics", cut, "--board", "9x6", "-o", out)
    assert res.returncode == 0, res.stderr
    assert "the video is damaged" in res.stderr and "truncated" in res.stderr
    assert 0 < yaml.safe_load(out.read_text())["images"]["total"] < FRAMES


@pytest.mark.parametrize("case", ["not_video", "no_frame", "fps", "every_on_folder"])
def test_bad_video_input_exits_2_with_one_line(recording: dict, tmp_path: Path, case: str) -> None:
    video: Path = recording["video"]
    src: Path = video
    extra: list[str] = []
    if case == "not_video":
        src = tmp_path / "clip.mp4"
        src.write_text("this is not a video\n" * 40)
    elif case == "no_frame":
        src = tmp_path / "head.mkv"
        src.write_bytes(video.read_bytes()[:600])
    elif case == "fps":
        extra = ["--fps", "30"]
    else:
        src, extra = recording["folder"], ["--every", "2"]
    out = tmp_path / "out" / "poses.npz"
    res = acscal("poses", src, "--intrinsics", recording["intr"], "-o", out, *extra, "--json")
    assert res.returncode == 2, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert not out.exists()
    assert json.loads(res.stdout)["ok"] is False


RUN_CONFIG = """\
schema: acscal/run-config
schema_version: 1
output: out
board: {cols: 9, rows: 6, square: 0.025}
cameras:
  a: {video: cam_a.mkv, max_frames: 12}
  b: {video: cam_b.avi, every: 1}
joint: {scenario: fixed_joint}
"""


def test_run_config_takes_video_files(tmp_path: Path) -> None:
    scene = render_scenario(tmp_path / "render", "fixed_joint", seed=0, frames=12, size=(640, 480))
    a, times_a = folder_to_video(scene / "cam_a", tmp_path / "cfg" / "cam_a.mkv", fps=15)
    folder_to_video(scene / "cam_b", tmp_path / "cfg" / "cam_b.avi", fps=15)
    config = tmp_path / "cfg" / "run.yaml"
    config.write_text(RUN_CONFIG, encoding="utf-8")
    first = acscal("run", config)
    assert first.returncode == 0, first.stderr
    run = tmp_path / "cfg" / "out"
    assert (run / "joint.yaml").is_file()
    art = PosesArtifact.load(run / "cam_a" / "poses.npz")
    names = art.trajectory.names
    assert names is not None and names[0].startswith("frame_")
    want = {f"frame_{i:06d}": t for i, t in enumerate(times_a)}
    np.testing.assert_allclose(art.trajectory.timestamps, [want[n] for n in names], atol=1e-9)
    assert yaml.safe_load((run / "cam_a" / "intrinsics.yaml").read_text())["video"]["kept"] == 12
    second = acscal("run", config)
    assert second.returncode == 0, second.stderr
    status = {}
    for line in second.stdout.splitlines():
        name, sep, rest = line.partition(": ")
        if sep and rest.split(" ")[0] in {"ran", "skipped", "reused"}:
            status[name] = rest.split(" ")[0]
    assert status and set(status.values()) == {"skipped"}, second.stdout
    assert {"intrinsics a", "poses a", "joint"} <= set(status), status
    assert a.is_file()


def test_sfm_poses_from_a_video(tmp_path: Path) -> None:
    from test_cli_sfm import FAST, _render

    folder = tmp_path / "frames"
    _render(folder, 12)
    video, times = folder_to_video(folder, tmp_path / "in" / "walk.mkv", fps=5, jitter=0.2)
    out, tum = tmp_path / "poses.npz", tmp_path / "poses.txt"
    res = acscal("poses", video, "--sfm", "--topic", "/cam", "-o", out)  # not a bag
    assert res.returncode == 2 and "--topic (/cam) applies to ROS bags" in res.stderr
    res = acscal("poses", video, "--sfm", "-o", out, "--tum", tum, "--every", "1", *FAST)
    assert res.returncode == 0, res.stderr
    assert "12 of 12 images registered" in res.stdout
    art = PosesArtifact.load(out)
    names = art.trajectory.names
    assert names is not None and names[0] == "frame_000000.png"
    # the frames' presentation times, not their order
    want = {f"frame_{i:06d}.png": t for i, t in enumerate(times)}
    np.testing.assert_allclose(art.trajectory.timestamps, [want[n] for n in names], atol=1e-9)
    assert art.header["video"]["kept"] == 12
    assert sorted(p.name for p in video.parent.iterdir()) == ["walk.mkv"]


def test_intrinsics_and_poses_from_a_ros_bag(recording: dict, tmp_path: Path) -> None:
    import cv2

    from sample_data_gen.bag import write_bag

    pngs = sorted(Path(recording["folder"]).glob("*.png"))
    stamps = [1_700_000_000_000_000_007 + k * 66_666_667 for k in range(len(pngs))]
    frames = (cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in pngs)
    bag = write_bag(tmp_path / "rec.bag", "/cam_a/image_raw", frames, stamps, encoding="bgr8")
    intr = tmp_path / "intrinsics.yaml"
    res = acscal("intrinsics", bag, "--topic", "/cam_a/image_raw", "--board", "9x6", "-o", intr)
    assert res.returncode == 0, res.stderr
    ref = yaml.safe_load(Path(recording["intr"]).read_text())
    doc = yaml.safe_load(intr.read_text())
    np.testing.assert_allclose(doc["camera_matrix"], ref["camera_matrix"], rtol=1e-9)
    assert doc["video"]["topic"] == "/cam_a/image_raw" and "bag" in doc["inputs"]
    npz, tum = tmp_path / "poses.npz", tmp_path / "poses.txt"
    res = acscal(
        "poses", bag, "--topic", "/cam_a/image_raw", "--intrinsics", intr, "-o", npz, "--tum", tum
    )
    assert res.returncode == 0, res.stderr
    assert f"{FRAMES} detections from a cache" in res.stdout  # the intrinsics' detections
    art = PosesArtifact.load(npz)
    names = art.trajectory.names
    assert names is not None
    want = {f"frame_{i:06d}": t for i, t in enumerate(stamps)}
    assert list(art.trajectory.timestamps_ns) == [want[n] for n in names]  # to the ns
    first = next(ln for ln in tum.read_text().splitlines() if not ln.startswith("#"))
    assert first.split()[0] == f"{want[names[0]] // 10**9}.{want[names[0]] % 10**9:09d}"
    bad = acscal("poses", bag, "--intrinsics", intr, "-o", tmp_path / "x.npz")
    assert bad.returncode == 2
    says = "a ROS bag needs --topic (its image topics: /cam_a/image_raw)"
    assert bad.stderr.strip().endswith(says) and len(bad.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.npz").exists()


BAG_CONFIG = """\
schema: acscal/run-config
schema_version: 1
output: out
board: {cols: 9, rows: 6, square: 0.025}
cameras:
  a: {bag: rig.bag, topic: /cam_a/image_raw}
  b: {bag: rig.bag, topic: /cam_b/image_raw, max_frames: 12}
joint: {scenario: fixed_joint}
"""


def test_run_config_points_two_cameras_at_one_bag(tmp_path: Path) -> None:
    import cv2

    from sample_data_gen.bag import write_bag_topics

    scene = render_scenario(tmp_path / "render", "fixed_joint", seed=0, frames=12, size=(640, 480))
    stamps = [1_600_000_000_000_000_000 + k * 50_000_001 for k in range(12)]
    topics = {
        f"/{cam}/image_raw": (
            [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted((scene / cam).glob("*.png"))],
            stamps,
        )
        for cam in ("cam_a", "cam_b")
    }
    write_bag_topics(tmp_path / "cfg" / "rig.bag", topics)
    config = tmp_path / "cfg" / "run.yaml"
    config.write_text(BAG_CONFIG, encoding="utf-8")
    res = acscal("run", config)
    assert res.returncode == 0, res.stderr
    run = tmp_path / "cfg" / "out"
    assert (run / "joint.yaml").is_file()
    for cam in ("cam_a", "cam_b"):
        art = PosesArtifact.load(run / cam / "poses.npz")
        names = art.trajectory.names
        assert names is not None
        want = [stamps[int(n.removeprefix("frame_"))] for n in names]
        assert list(art.trajectory.timestamps_ns) == want
        assert "header.stamp" in art.header["timestamps_from"]


def test_sfm_poses_from_a_ros_bag(tmp_path: Path) -> None:
    import cv2
    from test_cli_sfm import FAST, _render

    from sample_data_gen.bag import write_bag

    folder = tmp_path / "frames"
    _render(folder, 12)
    pngs = sorted(folder.glob("*.png"))
    stamps = [1_700_000_000_000_000_003 + k * 200_000_001 for k in range(len(pngs))]
    frames = (cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in pngs)
    bag = write_bag(tmp_path / "in" / "walk.bag", "/cam/image_raw", frames, stamps)
    out = tmp_path / "poses.npz"
    # a bag needs its topic: the one-line refusal lists the image topics
    res = acscal("poses", bag, "--sfm", "-o", out, *FAST)
    assert res.returncode == 2 and "/cam/image_raw" in res.stderr.strip().splitlines()[-1]
    assert not out.exists()
    res = acscal("poses", bag, "--topic", "/cam/image_raw", "--sfm", "-o", out, *FAST)
    assert res.returncode == 0, res.stderr
    assert "12 of 12 images registered" in res.stdout
    art = PosesArtifact.load(out)
    names = art.trajectory.names
    assert names is not None
    # each image's header.stamp, to the nanosecond
    want = [stamps[int(n.removeprefix("frame_").removesuffix(".png"))] for n in names]
    assert list(art.trajectory.timestamps_ns) == want
    assert "header.stamp" in art.header["timestamps_from"]
    assert "bag" in art.header["inputs"] and art.header["video"]["topic"] == "/cam/image_raw"
    assert sorted(p.name for p in bag.parent.iterdir()) == ["walk.bag"]
