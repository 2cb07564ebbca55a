"""Faults: ``acscal intrinsics``, ``poses`` and ``run`` killed (SIGKILL) mid-run, then rerun.

The rerun must give the same result as an uninterrupted run, reuse the finished work (the
detections cache, the run state) and leave no temporary file behind. The command runs in
its own process group, and the whole group (the detection workers too) is killed.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import cli_runner
import cv2
import numpy as np
import pytest
import yaml
from cli_runner import ACSCAL
from scipy.spatial.transform import Rotation

from acs_cli.io.detections import read_detections

SIZE = (640, 480)
BOARD = (9, 6)
SQUARE = 0.025
#: Images of the big folders (each run detects for a few seconds).
N_VIEWS = 100
N_FIXED = 40


# ----------------------------------------------------------------------------- rendering


def _texture(sq: int = 24) -> np.ndarray:
    cols, rows = BOARD
    tex = np.full(((rows + 5) * sq, (cols + 5) * sq), 255, np.uint8)
    for r in range(rows + 1):
        for c in range(cols + 1):
            if (r + c) % 2 == 0:
                tex[(r + 2) * sq : (r + 3) * sq, (c + 2) * sq : (c + 3) * sq] = 0
    return tex


def _camera() -> np.ndarray:
    f = 0.95 * SIZE[0]
    return np.array([[f, 0, SIZE[0] / 2 - 0.5], [0, f, SIZE[1] / 2 - 0.5], [0, 0, 1.0]])


def render(folder: Path, T_cam_board: np.ndarray, seed: int) -> None:
    """One PNG per pose: the board (white border) warped by the pose's homography."""
    sq = 24
    tex = _texture(sq)
    K = _camera()
    A = np.array([[SQUARE / sq, 0, -3 * SQUARE], [0, SQUARE / sq, -3 * SQUARE], [0, 0, 1.0]])
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    for i, T in enumerate(T_cam_board):
        H = K @ np.column_stack([T[:3, 0], T[:3, 1], T[:3, 3]]) @ A
        img = cv2.warpPerspective(tex, H, SIZE, flags=cv2.INTER_AREA, borderValue=150)
        img = cv2.GaussianBlur(img, (0, 0), 0.7)
        img = np.clip(img + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8)
        assert cv2.imwrite(str(folder / f"img_{i:04d}.png"), img)


def _centre() -> np.ndarray:
    return np.array([(BOARD[0] - 1) * SQUARE / 2, (BOARD[1] - 1) * SQUARE / 2, 0.0])


def random_views(n: int, seed: int) -> np.ndarray:
    """Board poses 10-35 degrees off the optical axis, the board filling half the image."""
    rng = np.random.default_rng(seed)
    dist = (BOARD[0] + 1) * SQUARE * 0.95
    out = np.zeros((n, 4, 4))
    for i in range(n):
        axis = rng.normal(size=3) * [1.0, 1.0, 0.3]
        angle = np.radians(rng.uniform(10, 35))
        R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()
        d = dist * rng.uniform(1.5, 1.9)
        t = np.array([rng.uniform(-0.1, 0.1) * d, rng.uniform(-0.1, 0.1) * d, d]) - R @ _centre()
        out[i, :3, :3], out[i, :3, 3], out[i, 3, 3] = R, t, 1.0
    return out


def fixed_joint_views(n: int, seed: int) -> np.ndarray:
    """A camera turning about a joint fixed in front of the board (world = board)."""
    rng = np.random.default_rng(seed)
    joint_w = _centre() + np.array([0.0, 0.0, -0.45])  # the camera side of the board is z < 0
    o_cam = np.array([0.03, -0.02, 0.08])  # the joint in the camera frame
    out = np.zeros((n, 4, 4))
    for i in range(n):
        R_wc = Rotation.from_rotvec(rng.uniform(-1, 1, 3) * np.radians(12)).as_matrix()
        t_wc = joint_w - R_wc @ o_cam
        out[i, :3, :3], out[i, :3, 3], out[i, 3, 3] = R_wc.T, -R_wc.T @ t_wc, 1.0
    return out


# ----------------------------------------------------------------------------- running


def _env() -> dict[str, str]:
    return dict(os.environ, COLUMNS="200", NO_COLOR="1")


def acscal(*args: str | Path) -> subprocess.CompletedProcess[str]:
    """A command that runs to its end (:func:`cli_runner.acscal`); kills exec the script."""
    res = cli_runner.acscal(*args)
    assert res.returncode == 0, (args, res.stdout, res.stderr)
    return res


def kill_when(args: list[str | Path], ready: Callable[[float], bool], what: str) -> float:
    """Start ``acscal args`` in its own process group; SIGKILL the group once ``ready``.

    ``ready(seconds since start)`` is polled every 5 ms. Returns when it was killed.
    Fails if the command ended first (the moment was never reached).
    """
    proc = subprocess.Popen(
        [str(ACSCAL), *map(str, args)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=_env(),
        start_new_session=True,
    )
    t0 = time.perf_counter()
    try:
        while proc.poll() is None and not ready(time.perf_counter() - t0):
            time.sleep(0.005)
        elapsed = time.perf_counter() - t0
        assert proc.poll() is None, f"the command ended before {what} (exit {proc.returncode})"
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:  # pragma: no cover - only when an assertion above failed
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    return elapsed


def n_cached(cache: Path) -> int:
    return len(read_detections(cache))


def cache_has(cache: Path, n: int) -> Callable[[float], bool]:
    def ready(_: float) -> bool:
        return cache.is_file() and n_cached(cache) >= n

    return ready


def after(seconds: float) -> Callable[[float], bool]:
    return lambda t: t >= seconds


def leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.rglob("*") if ".tmp" in p.name)


def reused(stdout: str) -> int:
    m = re.search(r"\((\d+) detections from (?:the|a) cache\)", stdout)
    assert m, stdout
    return int(m.group(1))


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Rendered folders and the results of uninterrupted runs."""
    root = tmp_path_factory.mktemp("faults")
    views = root / "views"
    render(views, random_views(N_VIEWS, 1), seed=1)
    fixed = root / "fixed"
    render(fixed, fixed_joint_views(N_FIXED, 2), seed=2)
    small = root / "small"
    render(small, random_views(12, 3), seed=3)
    base = root / "baseline"
    acscal("intrinsics", views, "-o", base / "views" / "intrinsics.yaml")
    acscal("intrinsics", small, "-o", base / "small" / "intrinsics.yaml")
    acscal(
        "poses", views, "--intrinsics", base / "small" / "intrinsics.yaml",
        "-o", base / "poses" / "poses.npz",
    )  # fmt: skip
    config = base / "run" / "run.yaml"
    config.parent.mkdir()
    config.write_text(RUN_CONFIG.format(images=fixed))
    acscal("run", config)
    return {
        "root": root,
        "views": views,
        "fixed": fixed,
        "small_intrinsics": base / "small" / "intrinsics.yaml",
        "intrinsics": base / "views" / "intrinsics.yaml",
        "poses": base / "poses" / "poses.npz",
        "joint": base / "run" / "run" / "joint.yaml",
    }


RUN_CONFIG = """\
schema: acscal/run-config
schema_version: 1
output: run
board: {{cols: 9, rows: 6, square: 0.025}}
cameras:
  a: {{images: {images}}}
intrinsics: {{from: joint}}
joint: {{scenario: fixed_joint}}
"""


# ----------------------------------------------------------------------------- intrinsics


def _same_intrinsics(got: Path, want: Path) -> None:
    a, b = yaml.safe_load(got.read_text()), yaml.safe_load(want.read_text())
    for key in ("camera_matrix", "distortion"):
        np.testing.assert_allclose(a[key], b[key], rtol=1e-9, atol=1e-12)
    assert a["images"]["used"] == b["images"]["used"]
    assert a["rms_px"] == pytest.approx(b["rms_px"], rel=1e-9)


@pytest.mark.parametrize("moment", ["cache-appeared", "cache-half-full", "early"])
def test_intrinsics_killed_then_rerun(data: dict[str, Path], tmp_path: Path, moment: str) -> None:
    out = tmp_path / "cam" / "intrinsics.yaml"
    cache = out.with_name("intrinsics.detections.npz")
    ready = {
        "cache-appeared": cache_has(cache, 1),
        "cache-half-full": cache_has(cache, N_VIEWS // 2),
        "early": after(float(np.random.default_rng(11).uniform(0.2, 0.8))),
    }[moment]
    kill_when(["intrinsics", data["views"], "-o", out], ready, moment)
    assert not out.exists()
    before = n_cached(cache)
    if moment != "early":
        assert before > 0
    res = acscal("intrinsics", data["views"], "-o", out)
    assert reused(res.stdout) == before  # every finished detection was reused
    _same_intrinsics(out, data["intrinsics"])
    assert n_cached(cache) == N_VIEWS
    assert leftovers(tmp_path) == []


def test_intrinsics_killed_twice(data: dict[str, Path], tmp_path: Path) -> None:
    """Two kills in a row, each after more progress, then a complete run."""
    out = tmp_path / "intrinsics.yaml"
    cache = out.with_name("intrinsics.detections.npz")
    args: list[str | Path] = ["intrinsics", data["views"], "-o", out]
    kill_when(args, cache_has(cache, 10), "10 cached detections")
    first = n_cached(cache)
    kill_when(args, cache_has(cache, first + 10), "10 more cached detections")
    second = n_cached(cache)
    assert second >= first + 10
    res = acscal(*args)
    assert reused(res.stdout) == second
    _same_intrinsics(out, data["intrinsics"])
    assert leftovers(tmp_path) == []


# ----------------------------------------------------------------------------- poses


@pytest.mark.parametrize("moment", ["cache-appeared", "cache-half-full"])
def test_poses_killed_then_rerun(data: dict[str, Path], tmp_path: Path, moment: str) -> None:
    out = tmp_path / "poses.npz"
    tum = tmp_path / "poses.tum"
    cache = out.with_name("poses.detections.npz")
    n = 1 if moment == "cache-appeared" else N_VIEWS // 2
    args: list[str | Path] = [
        "poses", data["views"], "--intrinsics", data["small_intrinsics"], "-o", out, "--tum", tum,
    ]  # fmt: skip
    kill_when(args, cache_has(cache, n), moment)
    assert not out.exists() and not tum.exists()
    before = n_cached(cache)
    assert before >= n
    res = acscal(*args)
    assert reused(res.stdout) == before
    with np.load(out) as got, np.load(data["poses"]) as want:
        for key in ("T_world_cam", "timestamps", "image_names", "corners", "reprojection_rms"):
            np.testing.assert_array_equal(got[key], want[key])
    assert tum.is_file()
    assert leftovers(tmp_path) == []


# ----------------------------------------------------------------------------- run


def _joint_numbers(path: Path) -> np.ndarray:
    joint = yaml.safe_load(path.read_text())["joint"]
    return np.array(joint["position_in_a"] + joint["position_in_a_std"], dtype=float)


@pytest.mark.parametrize("moment", ["intrinsics-cache", "state-written", "early"])
def test_run_killed_then_rerun(data: dict[str, Path], tmp_path: Path, moment: str) -> None:
    config = tmp_path / "run.yaml"
    config.write_text(RUN_CONFIG.format(images=data["fixed"]))
    run = tmp_path / "run"
    state = run / ".acscal-run.yaml"
    cache = run / "cam_a" / "intrinsics.detections.npz"
    ready = {
        "intrinsics-cache": cache_has(cache, 1),
        "state-written": lambda _: state.is_file(),  # the intrinsics stage has finished
        "early": after(float(np.random.default_rng(12).uniform(0.2, 0.8))),
    }[moment]
    kill_when(["run", config], ready, moment)
    assert not (run / "joint.yaml").exists()
    before = n_cached(cache)
    res = acscal("run", config)
    if moment == "state-written":
        assert "intrinsics a: skipped" in res.stdout, res.stdout
    else:
        assert "intrinsics a: ran" in res.stdout, res.stdout
    if moment == "intrinsics-cache":
        assert before > 0
    np.testing.assert_allclose(
        _joint_numbers(run / "joint.yaml"), _joint_numbers(data["joint"]), rtol=1e-9, atol=1e-12
    )
    assert leftovers(tmp_path) == []
    if moment == "state-written":
        again = acscal("run", config)  # and now everything is up to date
        assert "all 3 stages skipped" in again.stdout, again.stdout


def test_partial_files_of_killed_writers_are_cleaned(data: dict[str, Path], tmp_path: Path) -> None:
    """Temporary files a SIGKILL left (named with the dead writer's pid) do not survive the
    next successful write; one of a live writer (this process) is left alone."""
    dead = subprocess.Popen(["true"])
    dead.wait()
    out = tmp_path / "intrinsics.yaml"
    cache = out.with_name("intrinsics.detections.npz")
    stale = [
        tmp_path / f".{out.name}.{dead.pid}-0123456789ab.tmp.yaml",
        tmp_path / f".{cache.name}.{dead.pid}-0123456789ab.tmp.npz",
    ]
    live = tmp_path / f".{out.name}.{os.getpid()}-0123456789ab.tmp.yaml"
    for p in [*stale, live]:
        p.write_bytes(b"half a file")
    acscal("intrinsics", data["views"].parent / "small", "-o", out)
    assert [p for p in stale if p.exists()] == []
    assert live.exists()


def _children(pid: int) -> set[int]:
    found: set[int] = set()
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            found |= {int(c) for c in (task / "children").read_text().split()}
        except OSError:
            pass
    return found


def _running(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] not in ("Z", "X")  # not a zombie


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux's /proc")
def test_detection_workers_end_with_a_killed_acscal(data: dict[str, Path], tmp_path: Path) -> None:
    """SIGKILL to acscal alone (as the OOM killer does) must not leave its pool running."""
    args = ["intrinsics", data["views"], "-o", tmp_path / "i.yaml", "--workers", "2"]
    proc = subprocess.Popen(
        [str(ACSCAL), *map(str, args)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=_env(),
        start_new_session=True,
    )
    try:
        t0 = time.perf_counter()
        workers: set[int] = set()
        while proc.poll() is None and len(workers) < 2 and time.perf_counter() - t0 < 30:
            workers = _children(proc.pid)
            time.sleep(0.01)
        assert proc.poll() is None and workers, "the detection pool never started"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
        t0 = time.perf_counter()
        while any(_running(w) for w in workers) and time.perf_counter() - t0 < 10:
            time.sleep(0.05)
        assert not any(_running(w) for w in workers), "orphaned detection workers"
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
