"""``acscal run`` on a rendered two-camera ACS filming AprilGrids (issue 11): intrinsics,
poses, the fixed joint and the relative pose with their bundle adjustments, on partial views
of the targets (a different set of corners in each frame)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import acscal

from sample_data_gen.render_cli import main as render_main

#: Joint error bound (fraction of |O|) and relative pose bounds (degrees, metres) on these
#: 640x480 renders: measured about 0.2 %, 0.05 deg and 1 mm.
JOINT_TOL = 0.01
ROT_TOL_DEG = 0.3
TRANS_TOL = 0.005

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "configs" / "fixed_joint_aprilgrid.yaml"


def _angle_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    c = (np.trace(R1.T @ R2) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """Render the fixed-joint and general motions with an AprilGrid as the shipped config's
    comment says (four in ten frames a partial view; fewer frames, one sample a pixel),
    and run that config once."""
    root = tmp_path_factory.mktemp("acs_target_run")
    images = root / "demo_out" / "images_aprilgrid"
    for scenario in ("fixed_joint", "general"):
        args = ["--target", "aprilgrid", "--partial", "0.4", "--missing", "0"]
        args += ["--scenario", scenario, "--frames", "10", "--supersample", "1"]
        assert render_main([str(images), *args]) == 0
    config = root / "configs" / CONFIG.name
    config.parent.mkdir()
    shutil.copyfile(CONFIG, config)
    return {"root": root, "images": images, "run": acscal("run", config)}


def _load(path: Path) -> dict:
    return yaml.safe_load(path.read_text(encoding="utf-8"))


def test_the_whole_chain_runs_on_partial_views(workspace: dict[str, object]) -> None:
    run = workspace["run"]
    assert isinstance(run, subprocess.CompletedProcess)
    assert run.returncode == 0, run.stderr
    for stage in ("intrinsics a", "intrinsics b", "poses a", "poses b", "joint", "relpose"):
        assert f"{stage}: ran" in run.stdout, stage
    out = Path(str(workspace["root"])) / "demo_out" / "run_fixed_joint_aprilgrid"
    partial = 0
    for cam in ("cam_a", "cam_b"):
        assert _load(out / cam / "intrinsics.yaml")["target"]["target_type"] == "aprilgrid"
        for name in ("poses.npz", "poses_general.npz"):
            with np.load(out / cam / name) as z:
                seen = np.isfinite(z["corners"]).all(axis=2)
                assert z["board_points"].shape == (48, 3)
            assert seen.any(axis=1).all()  # every pose has corners
            partial += int(np.count_nonzero(~seen.all(axis=1)))
    print(f"{partial} poses from partial views")
    assert partial >= 4


def test_joint_and_relative_pose_match_the_truth(workspace: dict[str, object]) -> None:
    images = Path(str(workspace["images"]))
    out = Path(str(workspace["root"])) / "demo_out" / "run_fixed_joint_aprilgrid"
    truth = _load(images / "fixed_joint" / "truth.yaml")
    joint = _load(out / "joint.yaml")
    for cam in ("a", "b"):
        o_true = np.array(truth["joint"][f"position_in_{cam}"])
        err = np.linalg.norm(np.array(joint["joint"][f"position_in_{cam}"]) - o_true)
        print(f"joint {cam}: error {err * 1000:.2f} mm = {err / np.linalg.norm(o_true):.3%} |O|")
        assert err < JOINT_TOL * np.linalg.norm(o_true)
    truth_g = _load(images / "general" / "truth.yaml")
    rel = _load(out / "relpose.yaml")["relative_pose"]
    T_est, T_true = np.array(rel["T_b_a"]), np.array(truth_g["relative_pose"]["T_b_a"])
    angle = _angle_deg(T_est[:3, :3], T_true[:3, :3])
    t_true = np.array(truth_g["relative_pose"]["translation_b_in_a"])
    t_err = float(np.linalg.norm(np.array(rel["translation_b_in_a"]) - t_true))
    print(f"relpose: rotation error {angle:.3f} deg, translation error {t_err * 1000:.2f} mm")
    assert angle < ROT_TOL_DEG
    assert t_err < TRANS_TOL


def test_the_bundle_adjustments_ran_on_the_partial_views(workspace: dict[str, object]) -> None:
    """Both bundle adjustments ran, for both cameras, and the fixed-joint one used every
    pose, the partial views included."""
    out = Path(str(workspace["root"])) / "demo_out" / "run_fixed_joint_aprilgrid"
    joint = _load(out / "joint.yaml")
    rel = _load(out / "relpose.yaml")
    for doc in (joint, rel):
        assert "bundle adjustment" in doc["method"]
        sections = doc["quality"]["bundle_adjustment"]
        assert set(sections) == {"a", "b"}
        for section in sections.values():
            assert section["model"] == "pinhole" and section["frames"] >= 5
            assert 0 < section["rms_px"] < 0.2
    for cam in ("a", "b"):
        with np.load(out / f"cam_{cam}" / "poses.npz") as z:
            n_poses = z["corners"].shape[0]
        assert joint["quality"]["bundle_adjustment"][cam]["frames"] == n_poses
        assert joint["quality"]["frames"][cam]["rejected"] == []


def test_fisheye_intrinsics_on_the_target_have_a_std(
    workspace: dict[str, object], tmp_path: Path
) -> None:
    """``cv2.fisheye.calibrate`` gives no standard deviations; the artifact has them (from
    the Jacobian, the views' poses marginalised), near the pinhole calibration's."""
    images = Path(str(workspace["images"])) / "fixed_joint" / "cam_a"
    target = images.parent / "target.yaml"
    out = tmp_path / "fisheye.yaml"
    done = acscal("intrinsics", images, "--target", target, "--model", "fisheye", "-o", out)
    assert done.returncode == 0, done.stderr
    fisheye = _load(out)
    assert fisheye["model"] == "fisheye"
    std = fisheye["std"]
    assert std is not None and len(std["distortion"]) == 4
    assert all(np.isfinite(v) and v > 0 for v in [*std["distortion"], std["fx"], std["cy"]])
    pinhole = tmp_path / "pinhole.yaml"
    done = acscal("intrinsics", images, "--target", target, "-o", pinhole)
    assert done.returncode == 0, done.stderr
    pin = _load(pinhole)["std"]
    for key in ("fx", "fy", "cx", "cy"):
        print(f"{key}: fisheye std {std[key]:.3f} px, pinhole std {pin[key]:.3f} px")
        assert pin[key] / 3 < std[key] < 3 * pin[key]
