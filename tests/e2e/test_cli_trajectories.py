"""The ``acscal`` command end to end: real files in, artifacts and exit codes out."""

from __future__ import annotations

import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.io.trajectory import write_kitti, write_tum
from sample_data_gen import acs_sim


def load(path: Path) -> dict:
    return yaml.safe_load(path.read_text())


@pytest.fixture(scope="module")
def rig_files(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """One rig's fixed-joint, overlap and general recordings as TUM files (light noise)."""
    rng = np.random.default_rng(2024)
    rig = acs_sim.make_rig(rng)
    d = tmp_path_factory.mktemp("rig")
    seqs = {
        "fixed": acs_sim.fixed_joint_sequence(rng, rig, 30),
        "overlap": acs_sim.general_sequence(rng, rig, 30, shared_world=True),
        "general": acs_sim.general_sequence(rng, rig, 30),
    }
    files = {"rig": rig, "dir": d, "seqs": seqs}
    for name, seq in seqs.items():
        for cam, T in (("a", seq.T_wa_a), ("b", seq.T_wb_b)):
            noisy = acs_sim.add_pose_noise(rng, T, 0.3, 0.005)
            path = d / f"{name}_{cam}.tum"
            write_tum(path, seq.timestamps, noisy)
            files[f"{name}_{cam}"] = path
            scaled = d / f"{name}_{cam}_scaled.tum"
            write_tum(
                scaled,
                seq.timestamps,
                acs_sim.scale_translations(noisy, 0.8 if cam == "a" else 3.2),
            )
            files[f"{name}_{cam}_scaled"] = scaled
    return files


def test_every_command_help_has_an_example() -> None:
    """Every registered command (so a new one cannot slip through) shows an example."""
    import typer.main

    from acs_cli.cli.main import app

    commands = sorted(typer.main.get_command(app).commands)  # type: ignore[attr-defined]
    assert {"intrinsics", "poses", "joint", "relpose", "run", "report", "trajectory"} <= set(
        commands
    )
    for cmd in commands:
        res = acscal(cmd, "--help")
        assert res.returncode == 0, res.stderr
        assert "Example" in res.stdout, f"acscal {cmd} --help has no example"
        assert "acscal " + cmd in res.stdout.replace("\n", " "), cmd
    assert acscal("--version").stdout.startswith("acscal ")


def test_fixed_joint_then_relpose(rig_files: dict, tmp_path: Path) -> None:
    rig = rig_files["rig"]
    joint = tmp_path / "joint.yaml"
    res = acscal(
        "joint", "--fixed-joint", "--poses-a", rig_files["fixed_a"], "--poses-b",
        rig_files["fixed_b"], "-o", joint,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = load(joint)
    assert doc["schema"] == "acscal/joint" and doc["tool"]["name"] == "acscal"
    assert doc["inputs"]["poses_a"]["sha256"]
    o_a = np.array(doc["joint"]["position_in_a"])
    o_b = np.array(doc["joint"]["position_in_b"])
    std_a = np.array(doc["joint"]["position_in_a_std"])
    assert np.linalg.norm(o_a - rig.o_a) < 0.02
    assert np.linalg.norm(o_b - rig.o_b) < 0.02
    assert np.all(np.abs(o_a - rig.o_a) < 6 * std_a)

    rel = tmp_path / "relpose.yaml"
    res = acscal(
        "relpose", "--joint", joint, "--poses-a", rig_files["general_a"], "--poses-b",
        rig_files["general_b"], "-o", rel,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = load(rel)
    T_b_a = np.array(doc["relative_pose"]["T_b_a"])
    truth = rig_files["seqs"]["general"].T_b_a(0)
    assert se3.rotation_angle_deg(truth[:3, :3].T @ T_b_a[:3, :3]) < 1.5
    assert np.linalg.norm(T_b_a[:3, 3] - truth[:3, 3]) < 0.05
    T_a_b = se3.invert_transforms(T_b_a)
    np.testing.assert_allclose(doc["relative_pose"]["translation_b_in_a"], T_a_b[:3, 3], atol=1e-9)
    np.testing.assert_allclose(
        doc["relative_pose"]["rpy_deg"], se3.rpy_deg_from_matrix(T_a_b[:3, :3]), atol=1e-7
    )
    assert doc["quality"]["pairing"]["pairs"] == 30

    # exports that other tools read
    cv_file = tmp_path / "relpose_cv.yaml"
    assert acscal("export", rel, "--format", "opencv", "-o", cv_file).returncode == 0
    fs = cv2.FileStorage(str(cv_file), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("T_b_a").mat(), T_b_a, atol=1e-12)
    fs.release()
    chain = tmp_path / "camchain.yaml"  # Kalibr needs intrinsics (tests/e2e/test_cli_export.py)
    res = acscal("export", rel, "--format", "kalibr", "-o", chain)
    assert res.returncode == 2 and "missing for cam_a, cam_b" in res.stderr
    assert not chain.exists()


def test_paper_method_and_reference(rig_files: dict, tmp_path: Path) -> None:
    joint = tmp_path / "joint.yaml"
    args = ["--poses-a", rig_files["fixed_a"], "--poses-b", rig_files["fixed_b"]]
    assert acscal("joint", "--fixed-joint", *args, "--method", "paper", "-o", joint).returncode == 0
    rel = tmp_path / "rel.yaml"
    res = acscal(
        "relpose", "--joint", joint, "--poses-a", rig_files["general_a"], "--poses-b",
        rig_files["general_b"], "--method", "paper", "--reference", "7", "-o", rel,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = load(rel)
    assert doc["relative_pose"]["reference"] == 7
    assert doc["method"].startswith("paper")
    truth = rig_files["seqs"]["general"].T_b_a(7)
    T_b_a = np.array(doc["relative_pose"]["T_b_a"])
    assert se3.rotation_angle_deg(truth[:3, :3].T @ T_b_a[:3, :3]) < 1.5


def test_overlap_and_formats(rig_files: dict, tmp_path: Path) -> None:
    rig = rig_files["rig"]
    seq = rig_files["seqs"]["overlap"]
    kitti_a, kitti_b = tmp_path / "a.txt", tmp_path / "b.txt"
    write_kitti(kitti_a, seq.T_wa_a)
    write_kitti(kitti_b, seq.T_wb_b)
    out = tmp_path / "joint.yaml"
    res = acscal("joint", "--overlap", "--poses-a", kitti_a, "--poses-b", kitti_b, "-o", out)
    assert res.returncode == 0, res.stderr
    doc = load(out)
    assert doc["quality"]["pairing"]["by"] == "index"
    np.testing.assert_allclose(doc["joint"]["position_in_a"], rig.o_a, atol=1e-6)
    np.testing.assert_allclose(doc["joint"]["position_in_b"], rig.o_b, atol=1e-6)


def test_unknown_scale_and_self_calibration(rig_files: dict, tmp_path: Path) -> None:
    rig = rig_files["rig"]
    joint = tmp_path / "joint_scaled.yaml"
    res = acscal(
        "joint", "--fixed-joint", "--poses-a", rig_files["fixed_a_scaled"], "--poses-b",
        rig_files["fixed_b_scaled"], "-o", joint,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    rel = tmp_path / "rel_scaled.yaml"
    res = acscal(
        "relpose", "--unknown-scale", "--joint", joint, "--poses-a",
        rig_files["general_a_scaled"], "--poses-b", rig_files["general_b_scaled"], "-o", rel,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = load(rel)
    assert abs(doc["scale"]["phi_ba"] - 4.0) / 4.0 < 0.01
    truth = rig_files["seqs"]["general"].T_b_a(0)
    T_b_a = np.array(doc["relative_pose"]["T_b_a"])
    assert np.linalg.norm(T_b_a[:3, 3] / 3.2 - truth[:3, 3]) < 0.05

    metric = tmp_path / "joint_metric.yaml"
    args = ["--poses-a", rig_files["fixed_a"], "--poses-b", rig_files["fixed_b"]]
    assert acscal("joint", "--fixed-joint", *args, "-o", metric).returncode == 0
    rel_m = tmp_path / "rel_metric.yaml"
    res = acscal(
        "relpose", "--unknown-scale", "--joint-metric", metric, "--poses-a",
        rig_files["general_a_scaled"], "--poses-b", rig_files["general_b_scaled"], "-o", rel_m,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    scale = load(rel_m)["scale"]
    assert abs(scale["mu_a"] - 0.8) < 0.01 and abs(scale["mu_b"] - 3.2) < 0.04

    selfcal = tmp_path / "rel_self.yaml"
    res = acscal(
        "relpose", "--self-calibrate", "--poses-a", rig_files["general_a"], "--poses-b",
        rig_files["general_b"], "-o", selfcal,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = load(selfcal)
    assert np.linalg.norm(np.array(doc["joint"]["position_in_a"]) - rig.o_a) < 0.05
    assert np.linalg.norm(np.array(doc["joint"]["position_in_b"]) - rig.o_b) < 0.05


def _one_line_error(res: subprocess.CompletedProcess[str], code: int) -> str:
    assert res.returncode == code, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, res.stderr
    return lines[0]


def test_errors_are_one_line_with_exit_codes(rig_files: dict, tmp_path: Path) -> None:
    out = tmp_path / "out.yaml"
    msg = _one_line_error(
        acscal("joint", "--fixed-joint", "--poses-a", tmp_path / "missing.tum", "-o", out), 2
    )
    assert "missing.tum" in msg
    assert not out.exists()
    # output equal to an input
    _one_line_error(
        acscal(
            "joint", "--fixed-joint", "--poses-a", rig_files["fixed_a"], "-o", rig_files["fixed_a"]
        ),
        2,
    )
    # a trajectory where a joint file is expected: wrong kind of file
    msg = _one_line_error(
        acscal(
            "relpose",
            "--joint",
            rig_files["fixed_a"],
            "--poses-a",
            rig_files["general_a"],
            "--poses-b",
            rig_files["general_b"],
            "-o",
            out,
        ),
        2,
    )
    assert "fixed_a.tum" in msg
    # malformed line in a TUM file names the line
    bad = tmp_path / "bad.tum"
    bad.write_text("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n")
    msg = _one_line_error(acscal("joint", "--fixed-joint", "--poses-a", bad, "-o", out), 2)
    assert "bad.tum:2" in msg
    assert not out.exists()


def test_degenerate_motion_exit_3(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    hinge = acs_sim.make_rig(rng, hinge=True)
    seq = acs_sim.general_sequence(rng, hinge, 30, shared_world=True)
    write_tum(tmp_path / "a.tum", seq.timestamps, seq.T_wa_a)
    write_tum(tmp_path / "b.tum", seq.timestamps, seq.T_wb_b)
    out = tmp_path / "joint.yaml"
    args = ["--poses-a", tmp_path / "a.tum", "--poses-b", tmp_path / "b.tum", "-o", out]
    msg = _one_line_error(acscal("joint", "--overlap", *args), 3)
    assert "axis" in msg
    assert not out.exists()
    # a rigid pair: constant relative pose, no articulation
    T_a_b = seq.T_a_b[0]
    write_tum(tmp_path / "b.tum", seq.timestamps, seq.T_wa_a @ T_a_b)
    msg = _one_line_error(acscal("joint", "--overlap", *args), 3)
    assert "cannot be observed" in msg


def test_existing_artifact_survives_a_failed_run(rig_files: dict, tmp_path: Path) -> None:
    out = tmp_path / "joint.yaml"
    args = ["--poses-a", rig_files["fixed_a"], "--poses-b", rig_files["fixed_b"], "-o", out]
    assert acscal("joint", "--fixed-joint", *args).returncode == 0
    before = out.read_bytes()
    bad = tmp_path / "bad.tum"
    bad.write_text("0 0 0 0 nan 0 0 1\n")
    assert acscal("joint", "--fixed-joint", "--poses-a", bad, "-o", out).returncode == 2
    assert out.read_bytes() == before


def test_simulate_writes_study(tmp_path: Path) -> None:
    out = tmp_path / "study"
    res = acscal("simulate", "-o", out, "--trials", "2", "--levels", "2", "--frames", "20")
    assert res.returncode == 0, res.stderr
    rows = (out / "trials.csv").read_text().splitlines()
    assert len(rows) == 1 + 2 * 2 * 8  # header + levels x trials x (4 scenarios x 2 methods)
    pngs = sorted(out.glob("fig*.png"))
    assert len(pngs) == 8
    assert all(p.stat().st_size > 10_000 for p in pngs)
    summary = (out / "summary.csv").read_text()
    assert "paper" in summary and "refined" in summary


def test_overlap_cameras_labelling_the_board_in_opposite_orders(
    rig_files: dict, tmp_path: Path
) -> None:
    """Camera B rolled by more than 90 degrees from A labels the shared 9x6 board the other
    way round: its world is A's turned by half a turn. The joint stage notices (both
    labellings are tried when the poses NPZs carry the board) and says so."""
    from acs_cli.core.intrinsics import board_points
    from acs_cli.core.pnp import reversed_order_transform
    from acs_cli.io.trajectory import Trajectory, read_trajectory, write_npz_poses

    board = board_points(9, 6, 0.025)
    F = reversed_order_transform(9, 6, 0.025)
    paths = {}
    for cam in ("a", "b"):
        traj = read_trajectory(rig_files[f"overlap_{cam}"])
        T = traj.T_world_cam if cam == "a" else np.linalg.inv(F) @ traj.T_world_cam
        n = len(T)
        paths[cam] = tmp_path / f"{cam}.npz"
        write_npz_poses(
            paths[cam],
            Trajectory(traj.timestamps, T, source="test", format="npz", has_timestamps=True),
            {"board_points": board, "corners": np.zeros((n, len(board), 2))},
        )
    res = acscal(
        "joint", "--overlap", "--no-bundle", "--poses-a", paths["a"], "--poses-b", paths["b"],
        "-o", tmp_path / "joint.yaml",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = load(tmp_path / "joint.yaml")
    rig = rig_files["rig"]
    assert np.linalg.norm(np.array(doc["joint"]["position_in_a"]) - rig.o_a) < 0.02
    assert np.linalg.norm(np.array(doc["joint"]["position_in_b"]) - rig.o_b) < 0.02
    assert any("opposite orders" in w for w in doc["warnings"])
    # the same files as TUM (no board): nothing to turn, and the fit is far off or refused
    for cam in ("a", "b"):
        traj = read_trajectory(paths[cam])
        write_tum(tmp_path / f"{cam}.tum", traj.timestamps, traj.T_world_cam)
    res = acscal(
        "joint", "--overlap", "--poses-a", tmp_path / "a.tum", "--poses-b", tmp_path / "b.tum",
        "-o", tmp_path / "joint_tum.yaml",
    )  # fmt: skip
    if res.returncode == 0:
        off = load(tmp_path / "joint_tum.yaml")["joint"]["position_in_a"]
        assert np.linalg.norm(np.array(off) - rig.o_a) > 0.05
    else:
        assert res.returncode == 3, res.stderr


def test_trajectory_writes_nothing_when_an_output_cannot_be_written(
    rig_files: dict, tmp_path: Path
) -> None:
    """Issue 13: `trajectory` replaced cam_a.tum before it found that joint.tum could not be
    written; every output is now checked first."""
    rel = tmp_path / "relpose.yaml"
    poses = ["--poses-a", rig_files["general_a"], "--poses-b", rig_files["general_b"]]
    res = acscal("relpose", "--self-calibrate", *poses, "-o", rel)
    assert res.returncode == 0, res.stderr
    out = tmp_path / "traj"
    (out / "joint.tum").mkdir(parents=True)  # a folder where the third output goes
    (out / "cam_a.tum").write_text("# an earlier trajectory\n")
    res = acscal("trajectory", "--relpose", rel, *poses, "-o", out)
    assert res.returncode == 2 and "joint.tum" in res.stderr, res.stderr
    assert (out / "cam_a.tum").read_text() == "# an earlier trajectory\n"
    assert not (out / "cam_b.tum").exists()
