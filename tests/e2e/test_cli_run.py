"""``acscal run`` end to end on rendered images: fixed-joint motion, then general motion."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal

from sample_data_gen.render import render_scenario

STAGES_A = ["intrinsics a", "poses a", "poses general a", "joint", "relpose"]
STAGES_B = ["intrinsics b", "poses b", "poses general b"]

CONFIG = """\
schema: acscal/run-config
schema_version: 1
output: ../run
board: {cols: 9, rows: 6, square: 0.025}
cameras:
  a: {images: ../images/fixed_joint/cam_a, model: pinhole}
  b: {images: ../images/fixed_joint/cam_b}
joint: {scenario: fixed_joint, method: refined}
relpose:
  images: {a: ../images/general/cam_a, b: ../images/general/cam_b}
  method: refined
"""


def _status(stdout: str) -> dict[str, str]:
    """``{stage: status}`` from the progress lines ``<stage>: <status> ...``."""
    found: dict[str, str] = {}
    for line in stdout.splitlines():
        name, sep, rest = line.partition(": ")
        if sep and rest.split(" ")[0] in {"ran", "skipped", "reused"}:
            found[name] = rest.split(" ")[0]
    return found


def _outputs(run: Path) -> dict[str, bytes]:
    return {
        p.relative_to(run).as_posix(): p.read_bytes()
        for p in sorted(run.rglob("*"))
        if p.is_file() and p.suffix in {".yaml", ".npz", ".tum"} and p.name != ".acscal-run.yaml"
    }


def _angle_deg(R1: np.ndarray, R2: np.ndarray) -> float:
    c = (np.trace(R1.T @ R2) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


@pytest.fixture(scope="module")
def workspace(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """Render the images, write the config and run it once (shared by the tests)."""
    root = tmp_path_factory.mktemp("acs_run")
    for scenario in ("fixed_joint", "general"):
        render_scenario(root / "images", scenario, seed=0, frames=12, size=(640, 480))
    config = root / "configs" / "run.yaml"
    config.parent.mkdir()
    config.write_text(CONFIG, encoding="utf-8")
    t0 = time.perf_counter()
    first = acscal("run", config)
    seconds = time.perf_counter() - t0
    return {"root": root, "config": config, "first": first, "first_s": seconds}


def test_first_run_calibrates_everything(workspace: dict[str, object]) -> None:
    first = workspace["first"]
    assert isinstance(first, subprocess.CompletedProcess)
    assert first.returncode == 0, first.stderr
    assert set(_status(first.stdout).values()) == {"ran"}
    assert len(_status(first.stdout)) == len(STAGES_A) + len(STAGES_B)
    root = Path(str(workspace["root"]))
    run = root / "run"
    for cam in ("cam_a", "cam_b"):
        for name in ("intrinsics.yaml", "poses.npz", "poses.tum", "poses_general.npz"):
            assert (run / cam / name).is_file(), f"{cam}/{name}"
    assert (run / "joint.yaml").is_file() and (run / "relpose.yaml").is_file()
    assert (run / ".acscal-run.yaml").is_file()
    assert "RMS" in first.stdout and "T_b_a rpy" in first.stdout

    truth = yaml.safe_load((root / "images" / "fixed_joint" / "truth.yaml").read_text())
    joint = yaml.safe_load((run / "joint.yaml").read_text())["joint"]
    for cam in ("a", "b"):
        o_true = np.array(truth["joint"][f"position_in_{cam}"])
        err = np.linalg.norm(np.array(joint[f"position_in_{cam}"]) - o_true)
        print(f"joint error {cam}: {err * 1000:.2f} mm = {err / np.linalg.norm(o_true):.2%} |O|")
        assert err < 0.03 * np.linalg.norm(o_true)

    truth_g = yaml.safe_load((root / "images" / "general" / "truth.yaml").read_text())
    rel = yaml.safe_load((run / "relpose.yaml").read_text())["relative_pose"]
    T_est, T_true = np.array(rel["T_b_a"]), np.array(truth_g["relative_pose"]["T_b_a"])
    angle = _angle_deg(T_est[:3, :3], T_true[:3, :3])
    t_err = np.linalg.norm(np.array(rel["translation_b_in_a"]) - np.array(
        truth_g["relative_pose"]["translation_b_in_a"]
    ))  # fmt: skip
    print(f"relpose: rotation error {angle:.3f} deg, translation error {t_err * 1000:.2f} mm")
    print(f"first run {workspace['first_s']:.1f} s")
    assert angle < 2.0
    assert t_err < 0.03


def test_bundle_adjustment_on_the_run_corners(workspace: dict[str, object], tmp_path: Path) -> None:
    """By default the refined joint and relpose stages refine the result on the corners the
    poses NPZs carry (fixed joint per camera; general motion both cameras together), and
    `--no-bundle` turns that off."""
    root = Path(str(workspace["root"]))
    run = root / "run"
    doc = yaml.safe_load((run / "joint.yaml").read_text())  # the run's: bundle by default
    bundle = doc["quality"]["bundle_adjustment"]
    assert set(bundle) == {"a", "b"}
    assert "bundle adjustment" in doc["method"]
    truth = yaml.safe_load((root / "images" / "fixed_joint" / "truth.yaml").read_text())
    for cam in ("a", "b"):
        assert bundle[cam]["rms_px"] < 0.3
        K_true = np.array(truth[f"cam_{cam}"]["K"])
        assert abs(bundle[cam]["camera_matrix"][0][0] / K_true[0, 0] - 1) < 0.01
        assert set(bundle[cam]["intrinsics_std"]) >= {"fx", "fy", "cx", "cy", "k1"}
        o_true = np.array(truth["joint"][f"position_in_{cam}"])
        err = np.linalg.norm(np.array(doc["joint"][f"position_in_{cam}"]) - o_true)
        assert err < 0.03 * np.linalg.norm(o_true)
    rel = yaml.safe_load((run / "relpose.yaml").read_text())
    assert set(rel["quality"]["bundle_adjustment"]) == {"a", "b"}
    assert "bundle adjustment" in rel["method"]

    out = tmp_path / "joint_plain.yaml"
    res = acscal(
        "joint", "--fixed-joint", "--no-bundle", "--poses-a", run / "cam_a" / "poses.npz",
        "--poses-b", run / "cam_b" / "poses.npz", "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    plain = yaml.safe_load(out.read_text())
    assert "bundle_adjustment" not in plain["quality"]
    assert "bundle adjustment" not in plain["method"]


def test_a_poses_npz_under_another_name_still_gets_its_bundle_adjustment(
    workspace: dict[str, object], tmp_path: Path
) -> None:
    # issue 19: the bundle was chosen by the .npz suffix while the reader sniffs the content
    run = Path(str(workspace["root"])) / "run"
    for cam in ("a", "b"):  # their intrinsics file is found where the NPZ records it
        data = (run / f"cam_{cam}" / "poses.npz").read_bytes()
        (tmp_path / f"poses_{cam}.bin").write_bytes(data)
    out = tmp_path / "joint.yaml"
    res = acscal(
        "joint", "--fixed-joint", "--poses-a", tmp_path / "poses_a.bin",
        "--poses-b", tmp_path / "poses_b.bin", "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = yaml.safe_load(out.read_text())
    assert set(doc["quality"].get("bundle_adjustment", {})) == {"a", "b"}, res.stderr


def test_second_run_skips_and_changed_image_reruns_its_camera(
    workspace: dict[str, object],
) -> None:
    first = workspace["first"]
    assert isinstance(first, subprocess.CompletedProcess) and first.returncode == 0
    root = Path(str(workspace["root"]))
    config = Path(str(workspace["config"]))
    run = root / "run"
    before = _outputs(run)

    t0 = time.perf_counter()
    second = acscal("run", config)
    print(f"second run {time.perf_counter() - t0:.1f} s")
    assert second.returncode == 0, second.stderr
    status = _status(second.stdout)
    assert status == dict.fromkeys(STAGES_A + STAGES_B, "skipped")
    assert "all 8 stages skipped" in second.stdout
    assert _outputs(run) == before

    # change one image of camera A: its stages and the joint and relpose rerun, B's do not
    img_path = root / "images" / "fixed_joint" / "cam_a" / "img_00000.png"
    img = cv2.imread(str(img_path), cv2.IMREAD_GRAYSCALE)
    img[0, 0] = (int(img[0, 0]) + 1) % 256
    assert cv2.imwrite(str(img_path), img)
    third = acscal("run", config)
    assert third.returncode == 0, third.stderr
    status = _status(third.stdout)
    assert {s: status[s] for s in STAGES_A} == dict.fromkeys(STAGES_A, "ran")
    assert {s: status[s] for s in STAGES_B} == dict.fromkeys(STAGES_B, "skipped")
    after = _outputs(run)
    for name in ("cam_b/intrinsics.yaml", "cam_b/poses.npz", "cam_b/poses_general.npz"):
        assert after[name] == before[name]
    assert after["cam_a/intrinsics.yaml"] != before["cam_a/intrinsics.yaml"]

    forced = acscal("run", config, "--force", "--only", "joint")
    assert forced.returncode == 0, forced.stderr
    status = _status(forced.stdout)
    assert status == {"joint": "ran"}


def test_config_error_exits_2_naming_the_key(tmp_path: Path) -> None:
    config = tmp_path / "bad.yaml"
    config.write_text(CONFIG.replace("square: 0.025", "square: small"), encoding="utf-8")
    res = acscal("run", config)
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "'board.square'" in lines[0] and str(config) in lines[0]
    assert "Traceback" not in res.stderr


def test_a_joint_without_uncertainty_is_held_by_the_bundle_adjustment(
    workspace: dict[str, object], tmp_path: Path
) -> None:
    """A joint file with positions only is taken as exact by both the pose-based estimate
    and the bundle adjustment (which would otherwise re-estimate the joint from corners)."""
    run = Path(str(workspace["root"])) / "run"
    doc = yaml.safe_load((run / "joint.yaml").read_text())
    for key in ("position_in_a_std", "position_in_b_std", "covariance_a", "covariance_b"):
        doc["joint"].pop(key)
    given = tmp_path / "joint_exact.yaml"
    given.write_text(yaml.safe_dump(doc), encoding="utf-8")
    out = tmp_path / "relpose.yaml"
    res = acscal(
        "relpose", "--joint", given, "--poses-a", run / "cam_a" / "poses_general.npz",
        "--poses-b", run / "cam_b" / "poses_general.npz", "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    rel = yaml.safe_load(out.read_text())
    assert "bundle_adjustment" in rel["quality"]
    for cam in ("a", "b"):
        got = np.array(rel["joint"][f"position_in_{cam}"])
        np.testing.assert_allclose(got, doc["joint"][f"position_in_{cam}"], atol=1e-5)
