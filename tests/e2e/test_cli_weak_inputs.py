"""Inputs that look fine but cannot give the answer asked (issue 13, item 6), through the CLI.

Twenty frames of one board view (a tripod video) are refused (exit 3) instead of calibrating
to a focal length 40% off with a tiny std; a joint file in millimetres is converted for
trajectories in metres; a joint in an unknown unit, or an unknown-scale relative pose given
as a metric joint, is refused (exit 2) naming the file.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal
from test_bad_input import draw_views

from acs_cli.io.trajectory import write_tum
from acs_cli.stages.joint import JointConfig, run_joint
from sample_data_gen import acs_sim

TRUE_FX = 0.95 * 320  # draw_views' camera


def _repeat_with_noise(folder: Path, poses: int, copies: int, seed: int) -> Path:
    """``poses`` board views, each saved ``copies`` times with fresh sensor noise."""
    rng = np.random.default_rng(seed)
    for src in draw_views(folder, poses, seed=seed):
        img = cv2.imread(str(src), cv2.IMREAD_GRAYSCALE).astype(float)
        for k in range(1, copies):
            noisy = np.clip(img + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8)
            assert cv2.imwrite(str(src.with_name(f"{src.stem}_{k:02d}.png")), noisy)
    return folder


def test_tripod_video_refused(tmp_path: Path) -> None:
    images = _repeat_with_noise(tmp_path / "tripod", poses=1, copies=20, seed=3)
    out = tmp_path / "intrinsics.yaml"
    r = acscal("intrinsics", images, "--board", "9x6", "--square", "0.025", "-o", out)
    assert r.returncode == 3, r.stderr
    assert "20 views of the board" in r.stderr
    assert "only 1 distinct pose (a tripod video?)" in r.stderr
    assert "move the board or the camera" in r.stderr
    assert not out.exists()


def test_repeated_poses_warned_and_std_counts_each_pose_once(tmp_path: Path) -> None:
    images = _repeat_with_noise(tmp_path / "three", poses=4, copies=5, seed=5)
    out = tmp_path / "intrinsics.yaml"
    r = acscal("intrinsics", images, "--board", "9x6", "--square", "0.025", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "20 views show the board from only 4 distinct poses" in r.stderr
    doc = yaml.safe_load(out.read_text())
    assert any("4 distinct poses" in w for w in doc["warnings"])
    fx, fx_std = doc["camera_matrix"][0][0], doc["std"]["fx"]
    assert abs(fx - TRUE_FX) < 3 * fx_std
    distinct = _repeat_with_noise(tmp_path / "distinct", poses=4, copies=1, seed=5)
    r = acscal("intrinsics", distinct, "--board", "9x6", "--square", "0.025", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "distinct" not in r.stderr
    # 20 noisy copies of 4 views know no more than the 4 views
    assert fx_std >= 0.8 * yaml.safe_load(out.read_text())["std"]["fx"]


@pytest.fixture(scope="module")
def trajectories(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("units")
    rng = np.random.default_rng(4)
    rig = acs_sim.make_rig(rng)
    paths: dict[str, Path] = {}
    for name, seq in (
        ("fixed", acs_sim.fixed_joint_sequence(rng, rig, 20)),
        ("general", acs_sim.general_sequence(rng, rig, 20)),
    ):
        for cam, T in (("a", seq.T_wa_a), ("b", seq.T_wb_b)):
            paths[f"{name}_{cam}"] = root / f"{name}_{cam}.tum"
            noisy = acs_sim.add_pose_noise(rng, T, 0.2, 0.002)
            write_tum(paths[f"{name}_{cam}"], seq.timestamps, noisy)
    paths["joint"] = root / "joint.yaml"
    run_joint(paths["fixed_a"], paths["fixed_b"], paths["joint"], JointConfig())
    doc = yaml.safe_load(paths["joint"].read_text())
    j = doc["joint"]
    for key in ("position_in_a", "position_in_b", "position_in_a_std", "position_in_b_std"):
        j[key] = [1000.0 * v for v in j[key]]
    for key in ("covariance_a", "covariance_b"):
        j[key] = [[1e6 * v for v in row] for row in j[key]]
    j["units"] = doc["units"]["length"] = "mm"
    paths["joint_mm"] = root / "joint_mm.yaml"
    paths["joint_mm"].write_text(yaml.safe_dump(doc))
    return paths


def _relpose(
    paths: dict[str, Path], joint: Path, out: Path, *extra: str, flag: str = "--joint"
) -> subprocess.CompletedProcess[str]:
    return acscal(
        "relpose", flag, joint, "--poses-a", paths["general_a"],
        "--poses-b", paths["general_b"], "-o", out, *extra,
    )  # fmt: skip


def test_joint_in_mm_converted(trajectories: dict[str, Path], tmp_path: Path) -> None:
    r_m = _relpose(trajectories, trajectories["joint"], tmp_path / "m.yaml")
    r_mm = _relpose(trajectories, trajectories["joint_mm"], tmp_path / "mm.yaml")
    assert r_m.returncode == 0 and r_mm.returncode == 0, r_mm.stderr
    assert "converted to m (x 0.001)" in r_mm.stderr
    m = yaml.safe_load((tmp_path / "m.yaml").read_text())
    mm = yaml.safe_load((tmp_path / "mm.yaml").read_text())
    for key in ("position_in_a", "position_in_b"):
        np.testing.assert_allclose(mm["joint"][key], m["joint"][key], atol=1e-9)
    np.testing.assert_allclose(mm["relative_pose"]["T_b_a"], m["relative_pose"]["T_b_a"], atol=1e-9)
    assert any("in mm" in w for w in mm["warnings"])


def test_joint_unit_or_scale_refused(trajectories: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "out.yaml"
    r = _relpose(trajectories, trajectories["joint_mm"], out, "--length-unit", "px")
    assert r.returncode == 2
    assert f"{trajectories['joint_mm']}: the joint is in 'mm'" in r.stderr
    assert "trajectories are in 'px'" in r.stderr
    unknown = tmp_path / "unknown.yaml"
    r = _relpose(trajectories, trajectories["joint"], unknown, "--unknown-scale")
    assert r.returncode == 0, r.stderr
    r = _relpose(trajectories, unknown, out, "--unknown-scale", flag="--joint-metric")
    assert r.returncode == 2
    assert f"{unknown}: is an unknown-scale relpose.yaml" in r.stderr
    assert "not metres" in r.stderr
    assert not out.exists()
