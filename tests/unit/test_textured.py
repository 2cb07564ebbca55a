"""Rendered markerless sequences: files, truth, the joint, the room, texture, clocks, seeds."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.io.artifacts import read_yaml_artifact
from acs_cli.io.trajectory import read_trajectory
from sample_data_gen.__main__ import main
from sample_data_gen.textured import (
    ROOM_SIZE,
    make_room,
    markerless_motion,
    pinhole_rays,
    render_markerless,
    render_room_view,
)

SIZE = (160, 120)
FPS = 10.0
# coarse textures: a small room atlas keeps these tests fast
FAST: dict[str, Any] = {"size": SIZE, "texel": 0.02, "fps": FPS}


def _truth(folder: Path) -> dict[str, Any]:
    return read_yaml_artifact(folder / "truth.yaml", "render_truth")


def _image(folder: Path, cam: str, i: int) -> np.ndarray:
    img = cv2.imread(str(folder / cam / f"img_{i:05d}.png"), cv2.IMREAD_UNCHANGED)
    assert img is not None
    return img


@pytest.fixture(scope="module")
def sample(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return render_markerless(tmp_path_factory.mktemp("markerless"), seed=4, frames=6, **FAST)


def test_files_and_truth_written(sample: Path) -> None:
    truth = _truth(sample)
    assert sample.name == "markerless"
    assert truth["scenario"] == "markerless" and truth["n_frames"] == 6
    assert truth["image_size"] == list(SIZE) and truth["fps"] == FPS
    assert truth["time_offset_s"] == 0.0
    stamps = np.arange(6) / FPS
    for name, tum in (("cam_a", "truth_a.tum"), ("cam_b", "truth_b.tum")):
        cam = truth[name]
        assert cam["model"] == "pinhole" and cam["truth_trajectory"] == tum
        K = np.array(cam["K"])
        assert K.shape == (3, 3) and np.allclose(cam["dist"], 0.0)
        assert 0.8 * SIZE[0] <= K[0, 0] <= 0.9 * SIZE[0]
        T = np.array(cam["T_world_cam"])
        assert T.shape == (6, 4, 4)
        traj = read_trajectory(sample / tum, "tum")
        assert np.allclose(traj.timestamps, stamps)
        assert np.allclose(traj.T_world_cam, T, atol=1e-6)
        for i in range(6):
            img = _image(sample, name, i)
            assert img.shape == (SIZE[1], SIZE[0]) and img.dtype == np.uint8


def test_joint_constraint_holds_on_the_truth(sample: Path) -> None:
    truth = _truth(sample)
    T_a = np.array(truth["cam_a"]["T_world_cam"])
    T_b = np.array(truth["cam_b"]["T_world_cam"])
    o_a = np.array(truth["joint"]["position_in_a"])
    o_b = np.array(truth["joint"]["position_in_b"])
    assert 0.2 <= np.linalg.norm(o_a) <= 0.5 and 0.2 <= np.linalg.norm(o_b) <= 0.5
    j_a = se3.transform_points(T_a, o_a)
    assert np.allclose(j_a, se3.transform_points(T_b, o_b), atol=1e-9)
    assert np.allclose(j_a, truth["joint"]["position_in_world"], atol=1e-9)
    T_a_b = np.array(truth["T_a_b"])
    assert np.allclose(se3.invert_transforms(T_a) @ T_b, T_a_b, atol=1e-9)
    assert np.allclose(np.array(truth["relative_pose"]["T_b_a"]) @ T_a_b[0], np.eye(4))
    # the joint bends between frames; the cameras look in clearly different directions
    assert np.ptp(T_a_b[:, :3, :3], axis=0).max() > 0.05
    lo, _hi = truth["motion"]["optical_axes_angle_deg"]
    assert lo > 60.0


def test_cameras_stay_inside_the_room(sample: Path) -> None:
    truth = _truth(sample)
    size = np.array(truth["room"]["size"])
    assert np.allclose(size, ROOM_SIZE)
    for name in ("cam_a", "cam_b"):
        c = np.array(truth[name]["T_world_cam"])[:, :3, 3]
        assert np.all(c >= 0.5) and np.all(c <= size - 0.5)
        depth = np.array(truth[name]["depth_range_m"])
        assert depth.shape == (6, 2)
        assert np.all(depth[:, 0] > 0.3) and np.all(depth[:, 1] < np.linalg.norm(size))
        assert np.all(depth[:, 1] > 1.2 * depth[:, 0])  # depth varies over the view: parallax
    assert min(truth["motion"]["min_clearance_m"].values()) >= 0.5


def test_images_are_textured(sample: Path) -> None:
    for name in ("cam_a", "cam_b"):
        for i in (0, 5):
            img = _image(sample, name, i)
            assert img.std() > 20.0
            corners = cv2.goodFeaturesToTrack(img, 1000, 0.01, 3)
            assert corners is not None and len(corners) > 200


def test_textures_differ_per_face_and_do_not_repeat() -> None:
    room = make_room(1, texel=0.02)
    rows = np.diff(np.append(room.row0, room.atlas.shape[0] + 1)).astype(int) - 2
    faces = [
        room.atlas[int(r0) : int(r0) + n, 1:101] for r0, n in zip(room.row0, rows, strict=True)
    ]
    for f in faces:
        assert f.std() > 0.05
    # no tile repeats: a patch matches only itself within its face
    wall = faces[4]
    patch = wall[10:42, 10:42]
    score = cv2.matchTemplate(wall, patch, cv2.TM_CCOEFF_NORMED)
    assert score[10, 10] == pytest.approx(1.0, abs=1e-4)
    score[6:15, 6:15] = -1.0  # the patch itself and its immediate neighbours
    assert score.max() < 0.6
    assert not np.allclose(faces[0][:50], faces[1][:50], atol=0.05)


def test_motion_is_smooth_and_spans_the_requested_ranges() -> None:
    duration = 2.0
    motion = markerless_motion(0, np.array(ROOM_SIZE), duration)
    t = np.linspace(0.0, duration, 201)
    T_a = motion.T_world_a(t)
    p = T_a[:, :3, 3]
    assert 1.0 <= np.linalg.norm(np.ptp(p, axis=0)) <= 2.0
    rot = se3.rotation_angle_deg(np.einsum("ji,njk->nik", T_a[0, :3, :3], T_a[:, :3, :3]))
    assert rot.max() > 10.0
    Q = motion.T_a_b(t)[:, :3, :3] @ motion.rig.R0.T
    assert 10.0 < se3.rotation_angle_deg(Q).max() < 60.0
    # twice differentiable: second differences converge (bounded acceleration)
    h = 1e-3
    tt = np.linspace(0.1, 1.9, 50)
    acc = (
        motion.T_world_b(tt + h)[:, :3, 3]
        - 2 * motion.T_world_b(tt)[:, :3, 3]
        + motion.T_world_b(tt - h)[:, :3, 3]
    ) / h**2
    assert np.abs(acc).max() < 50.0


def test_render_room_view_from_the_centre() -> None:
    room = make_room(0, texel=0.02)
    K = np.array([[80.0, 0.0, 39.5], [0.0, 80.0, 29.5], [0.0, 0.0, 1.0]])
    rays = pinhole_rays(K, (80, 60), 2)
    assert rays.shape == (2, 120, 160)
    T = np.eye(4)
    T[:3, 3] = [4.0, 3.0, 1.5]
    T[:3, :3] = np.diag([1.0, -1.0, -1.0])  # optical axis straight down: the floor, 1.5 m away
    img, (d_min, d_max) = render_room_view(
        room, rays, T, supersample=2, noise_sigma=0.0, rng=np.random.default_rng(0)
    )
    assert img.shape == (60, 80) and img.dtype == np.uint8
    assert d_min == pytest.approx(1.5) and d_max == pytest.approx(1.5)


def _hashes(folder: Path) -> dict[str, str]:
    return {
        str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.name != "truth.yaml"
    }


def test_same_seed_same_output(tmp_path: Path) -> None:
    a = render_markerless(tmp_path / "a", seed=2, frames=3, **FAST)
    b = render_markerless(tmp_path / "b", seed=2, frames=3, **FAST)
    c = render_markerless(tmp_path / "c", seed=3, frames=3, **FAST)
    assert _hashes(a) == _hashes(b)
    assert _hashes(a) != _hashes(c)
    ta, tb = _truth(a), _truth(b)
    for key in ("cam_a", "cam_b", "joint", "T_a_b", "motion", "room"):
        assert ta[key] == tb[key]


def test_time_offset_convention(tmp_path: Path) -> None:
    """B's clock runs time_offset_s ahead: its image stamped t shows the rig at
    t - time_offset_s; A is unaffected."""
    kw = {"seed": 5, "frames": 6, "noise_sigma": 0.0, **FAST}
    sync = render_markerless(tmp_path / "sync", **kw)
    dt = -2 / FPS  # B's clock behind: its image stamped t shows the rig at t + 2 frames
    late = render_markerless(tmp_path / "late", time_offset_s=dt, **kw)
    ts, tl = _truth(sync), _truth(late)
    assert tl["time_offset_s"] == pytest.approx(dt)
    assert np.allclose(tl["cam_b"]["rig_time_s"], np.arange(6) / FPS - dt)
    assert ts["cam_a"]["T_world_cam"] == tl["cam_a"]["T_world_cam"]
    T_b_sync = np.array(ts["cam_b"]["T_world_cam"])
    T_b_late = np.array(tl["cam_b"]["T_world_cam"])
    assert np.allclose(T_b_late[:4], T_b_sync[2:], atol=1e-9)
    for i in range(4):
        assert np.array_equal(_image(late, "cam_a", i), _image(sync, "cam_a", i))
        diff = np.abs(_image(late, "cam_b", i).astype(int) - _image(sync, "cam_b", i + 2))
        assert diff.max() <= 1
    # B's file keeps B's own stamps; the joint holds at equal rig times
    assert np.allclose(read_trajectory(late / "truth_b.tum", "tum").timestamps, np.arange(6) / FPS)
    T_a = np.array(tl["cam_a"]["T_world_cam"])
    T_b_at_a = np.array(tl["T_world_b_at_a_times"])
    o_a, o_b = (np.array(tl["joint"][k]) for k in ("position_in_a", "position_in_b"))
    assert np.allclose(se3.transform_points(T_a, o_a), se3.transform_points(T_b_at_a, o_b))
    assert np.allclose(T_b_at_a, T_b_sync, atol=1e-9)
    assert not np.allclose(se3.transform_points(T_a, o_a), se3.transform_points(T_b_late, o_b))


def test_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="frames"):
        render_markerless(tmp_path, frames=0)
    with pytest.raises(ValueError, match="too small"):
        render_markerless(tmp_path, size=(8, 8))
    with pytest.raises(ValueError, match="fps"):
        render_markerless(tmp_path, fps=0.0)
    with pytest.raises(ValueError, match="remap"):
        make_room(0, texel=0.0001)
    assert not any(tmp_path.iterdir())


def test_cli_writes_the_markerless_sample(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    calls: list[tuple[Any, dict[str, Any]]] = []

    def fake(out_dir: Any, **kwargs: Any) -> Path:
        calls.append((out_dir, kwargs))
        return Path(out_dir) / "markerless"

    monkeypatch.setattr("sample_data_gen.__main__.render_markerless", fake)
    assert main([str(tmp_path / "m"), "--markerless", "--seed", "3"]) == 0
    assert (
        main([str(tmp_path / "m"), "--markerless", "--frames", "9", "--time-offset", "-0.04"]) == 0
    )
    assert calls[0] == (str(tmp_path / "m"), {"seed": 3, "frames": 60, "time_offset_s": 0.0})
    assert calls[1][1] == {"seed": 0, "frames": 9, "time_offset_s": -0.04}
    assert "markerless" in capsys.readouterr().out
    for bad in (
        ["--rig"],
        ["--scenario", "general"],
        ["--hinge"],
        ["--rot-noise", "0"],
        ["--mu-b", "2"],
        ["--time-offset", "nan"],
    ):
        with pytest.raises(SystemExit):
            main([str(tmp_path / "x"), "--markerless", *bad])
    with pytest.raises(SystemExit):
        main([str(tmp_path / "x"), "--time-offset", "0.1"])  # needs --markerless
    assert len(calls) == 2
