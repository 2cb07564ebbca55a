"""The sample rig writer (``python -m sample_data_gen OUT --rig``): files, truth, config."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from acs_cli.core import se3
from acs_cli.io.artifacts import read_yaml_artifact
from acs_cli.io.trajectory import read_trajectory
from sample_data_gen.__main__ import main
from sample_data_gen.rig_sim import SAMPLE_JOINTS
from sample_data_gen.writer import RIG_NOISE, write_rig_recording

CAMS = ["cam0", "cam1", "cam2", "cam3", "cam4"]
REPO = Path(__file__).resolve().parents[2]


def _arr(x: object) -> np.ndarray:
    return np.asarray(x, dtype=float)


def test_rig_files_truth_and_tum(tmp_path: Path) -> None:
    rec = write_rig_recording(tmp_path / "rig", seed=4, frames=25)
    out = tmp_path / "rig"
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [f"{c}.tum" for c in CAMS] + ["truth.yaml", "config.yaml"]
    )
    # TUM round trip: what the file holds is the recording's trajectory of each camera
    for c in CAMS:
        traj = read_trajectory(out / f"{c}.tum", "tum")
        np.testing.assert_allclose(traj.timestamps, rec.timestamps, atol=1e-9)
        np.testing.assert_allclose(traj.T_world_cam, rec.T_wc_c[c], atol=1e-12)
    # truth matches the recording
    truth = read_yaml_artifact(out / "truth.yaml", "rig_truth")
    assert truth["reference"] == {"camera": "cam0", "frame": 0}
    assert truth["length_unit"] == "m" and truth["n_frames"] == 25 and truth["seed"] == 4
    assert truth["noise"]["sigma_rot_deg"] == RIG_NOISE[0]
    assert truth["noise"]["sigma_trans"] == RIG_NOISE[1]
    assert list(truth["cameras"]) == CAMS
    T_true = rec.T_cam_ref(0)
    for c in CAMS:
        cam = truth["cameras"][c]
        assert cam["poses"] == f"{c}.tum"
        np.testing.assert_allclose(_arr(cam["T_cam_ref"]), T_true[c], atol=1e-15)
        assert cam["unknown_scale"] is (c == "cam4")
        assert cam["mu"] == rec.mu[c] and cam["scale"] == pytest.approx(1.0 / rec.mu[c])
        if c != "cam4":
            assert cam["mu"] == 1.0
        else:
            assert 0.3 <= cam["mu"] <= 3.0
    np.testing.assert_allclose(_arr(truth["cameras"]["cam0"]["T_cam_ref"]), np.eye(4), atol=1e-12)
    assert [(n, tuple(j["between"]), j["type"]) for n, j in truth["joints"].items()] == list(
        SAMPLE_JOINTS
    )
    for name, j in truth["joints"].items():
        e = rec.edges[name]
        p, q = e.between
        np.testing.assert_allclose(
            _arr(j["T_q_p"]), T_true[q] @ se3.invert_transforms(T_true[p]), atol=1e-12
        )
        if e.type == "rigid":
            assert "position_in" not in j and "axis_in" not in j
            continue
        np.testing.assert_allclose(_arr(j["position_in"][p]), e.o_p, atol=1e-15)
        np.testing.assert_allclose(_arr(j["position_in"][q]), e.o_q, atol=1e-15)
        # the joint point is one physical point in both cameras at the reference instant
        np.testing.assert_allclose(se3.transform_points(_arr(j["T_q_p"]), e.o_p), e.o_q, atol=1e-9)
        if e.type == "hinge":
            assert e.axis_p is not None and e.axis_q is not None
            np.testing.assert_allclose(_arr(j["axis_in"][p]), e.axis_p, atol=1e-15)
            np.testing.assert_allclose(_arr(j["axis_in"][q]), e.axis_q, atol=1e-15)
            np.testing.assert_allclose(_arr(j["T_q_p"])[:3, :3] @ e.axis_p, e.axis_q, atol=1e-9)
        else:
            assert "axis_in" not in j


def test_rig_noise_and_scale(tmp_path: Path) -> None:
    """The files carry the noise asked for (0.3 deg, 1 cm per axis) and cam4's scale."""
    rec = write_rig_recording(tmp_path, seed=1, frames=400)
    for c in ("cam0", "cam4"):  # metric, and unknown scale
        T_file = read_trajectory(tmp_path / f"{c}.tum", "tum").T_world_cam
        T_W = rec.T_W_c[c]
        # file = [R_G R_W Exp(n_r), mu (R_G t_W + t_G + n_t)] with a random world G
        R_G, _ = se3.project_to_rotation(
            np.einsum("nij,nkj->ik", T_file[:, :3, :3], T_W[:, :3, :3])
        )
        n_r = np.einsum("nji,kj,nkl->nil", T_W[:, :3, :3], R_G, T_file[:, :3, :3])
        ang = se3.rotation_angle_deg(n_r)
        # |theta| of N(0, s^2 I) in 3-D has RMS sqrt(3) s
        assert np.sqrt(np.mean(ang**2)) == pytest.approx(np.sqrt(3) * RIG_NOISE[0], rel=0.1)
        resid = T_file[:, :3, 3] / rec.mu[c] - T_W[:, :3, 3] @ R_G.T
        resid -= resid.mean(axis=0)  # t_G
        assert np.sqrt(np.mean(resid**2)) == pytest.approx(RIG_NOISE[1], rel=0.1)
    assert rec.unknown_scale == {c: c == "cam4" for c in CAMS}
    assert rec.mu["cam4"] != 1.0 and all(rec.mu[c] == 1.0 for c in CAMS[:4])


def test_rig_config_parses(tmp_path: Path) -> None:
    write_rig_recording(tmp_path, seed=0, frames=5)
    doc = yaml.safe_load((tmp_path / "config.yaml").read_text(encoding="utf-8"))
    assert doc == {
        "schema": "acscal/run-config",
        "schema_version": 2,
        "output": "out/",
        "reference": {"camera": "cam0", "frame": 0},
        "cameras": {
            "cam0": {"poses": "cam0.tum"},
            "cam1": {"poses": "cam1.tum"},
            "cam2": {"poses": "cam2.tum"},
            "cam3": {"poses": "cam3.tum"},
            "cam4": {"poses": "cam4.tum", "scale": "unknown"},
        },
        "joints": {
            "r01": {"between": ["cam0", "cam1"], "type": "rigid"},
            "j02": {"between": ["cam0", "cam2"], "type": "ball"},
            "j23": {"between": ["cam2", "cam3"], "type": "hinge"},
            "r34": {"between": ["cam3", "cam4"], "type": "rigid"},
        },
    }
    # the run config parser takes it, paths resolved against the config's folder
    from acs_cli.stages.rig import RigRunConfig
    from acs_cli.stages.run import load_run_config

    config = load_run_config(tmp_path / "config.yaml")
    assert isinstance(config, RigRunConfig)
    assert config.output == tmp_path / "out"
    assert config.reference_camera == "cam0" and config.reference_frame == 0
    assert [config.cameras[c].poses for c in CAMS] == [tmp_path / f"{c}.tum" for c in CAMS]
    assert [c for c in CAMS if config.cameras[c].unknown_scale] == ["cam4"]


def test_example_config_matches_the_sample(tmp_path: Path) -> None:
    """configs/rig.yaml names the files `make demo` writes, with the sample's joints."""
    example = yaml.safe_load((REPO / "configs" / "rig.yaml").read_text(encoding="utf-8"))
    write_rig_recording(tmp_path, seed=0, frames=5)
    sample = yaml.safe_load((tmp_path / "config.yaml").read_text(encoding="utf-8"))
    for key in ("schema", "schema_version", "reference", "joints"):
        assert example[key] == sample[key]
    assert list(example["cameras"]) == list(sample["cameras"])
    for c, cam in example["cameras"].items():
        assert cam["poses"] == f"../demo_out/rig/{c}.tum"
        assert cam.get("scale") == sample["cameras"][c].get("scale")
    from acs_cli.stages.run import load_run_config

    load_run_config(REPO / "configs" / "rig.yaml")


def test_cli_rig(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(tmp_path / "r"), "--rig", "--seed", "2", "--frames", "7"]) == 0
    assert "rig:" in capsys.readouterr().out
    truth = read_yaml_artifact(tmp_path / "r" / "truth.yaml", "rig_truth")
    assert truth["n_frames"] == 7 and truth["seed"] == 2
    assert len(read_trajectory(tmp_path / "r" / "cam3.tum", "tum")) == 7
    assert main([str(tmp_path / "d"), "--rig"]) == 0
    truth = read_yaml_artifact(tmp_path / "d" / "truth.yaml", "rig_truth")
    assert truth["n_frames"] == 100
    assert truth["noise"]["sigma_rot_deg"] == 0.3 and truth["noise"]["sigma_trans"] == 0.01
    for bad in (["--scenario", "general"], ["--hinge"], ["--mu-a", "2"], ["--frames", "0"]):
        with pytest.raises(SystemExit) as exc:
            main([str(tmp_path / "x"), "--rig", *bad])
        assert exc.value.code == 2
    assert not (tmp_path / "x").exists()
