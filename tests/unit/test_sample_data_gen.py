"""The synthetic-recording writer: files, truth and their consistency."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.io.artifacts import read_yaml_artifact
from acs_cli.io.trajectory import read_trajectory
from sample_data_gen.__main__ import main
from sample_data_gen.writer import (
    SAMPLE_MU_A,
    SAMPLE_MU_B,
    write_sample_set,
    write_scenario,
)


def _load(folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    a = read_trajectory(folder / "cam_a.tum", "tum")
    b = read_trajectory(folder / "cam_b.tum", "tum")
    truth = read_yaml_artifact(folder / "truth.yaml", "truth")
    np.testing.assert_array_equal(a.timestamps, b.timestamps)
    return a.T_world_cam, b.T_world_cam, a.timestamps, truth


def _arr(x: object) -> np.ndarray:
    return np.asarray(x, dtype=float)


@pytest.mark.parametrize("scenario", ["fixed_joint", "overlap", "general"])
def test_files_and_truth_keys(tmp_path: Path, scenario: str) -> None:
    out = write_scenario(tmp_path / scenario, scenario, seed=3, frames=12)
    assert out == tmp_path / scenario
    Ta, Tb, t, truth = _load(out)
    assert Ta.shape == Tb.shape == (12, 4, 4)
    assert np.all(np.diff(t) > 0)
    assert truth["scenario"] == scenario
    assert truth["seed"] == 3
    for key in ("position_in_a", "position_in_b"):
        assert 1.0 <= np.linalg.norm(_arr(truth["joint"][key])) <= 2.0
    rel = truth["relative_pose"]
    assert rel["reference"] == 0
    T_b_a = _arr(rel["T_b_a"])
    T_a_b = se3.invert_transforms(T_b_a)
    np.testing.assert_allclose(rel["translation_b_in_a"], T_a_b[:3, 3], atol=1e-12)
    np.testing.assert_allclose(se3.matrix_from_rpy_deg(rel["rpy_deg"]), T_a_b[:3, :3], atol=1e-12)
    assert truth["scale"] == {"mu_a": 1.0, "mu_b": 1.0, "phi_ba": 1.0}
    assert truth["noise"]["sigma_rot_deg"] == 0.0
    assert truth["hinge_axis_in_a"] is None


def test_fixed_joint_truth_satisfies_the_constraint(tmp_path: Path) -> None:
    Ta, Tb, _, truth = _load(write_scenario(tmp_path, "fixed_joint", seed=11))
    joint = truth["joint"]
    for T, o, p_w in (
        (Ta, joint["position_in_a"], joint["position_in_world_a"]),
        (Tb, joint["position_in_b"], joint["position_in_world_b"]),
    ):
        p = se3.transform_points(T, _arr(o))  # R_i o + t_i: one world point throughout
        np.testing.assert_allclose(p, np.broadcast_to(_arr(p_w), p.shape), atol=1e-9)
    # the two world joints are one point
    T_wb_wa = _arr(truth["T_wb_wa"])
    np.testing.assert_allclose(
        se3.transform_points(T_wb_wa, _arr(joint["position_in_world_a"])),
        joint["position_in_world_b"],
        atol=1e-9,
    )


def test_general_truth_composes(tmp_path: Path) -> None:
    Ta, Tb, _, truth = _load(write_scenario(tmp_path, "general", seed=5, frames=20))
    T_b_a = _arr(truth["relative_pose"]["T_b_a"])
    T_wb_wa = _arr(truth["T_wb_wa"])
    # B's reference pose = X A's reference pose inv(T_b_a)
    np.testing.assert_allclose(Tb[0] @ T_b_a, T_wb_wa @ Ta[0], atol=1e-9)
    # at every frame the joint is one physical point
    o_a, o_b = _arr(truth["joint"]["position_in_a"]), _arr(truth["joint"]["position_in_b"])
    j_a = se3.transform_points(T_wb_wa @ Ta, o_a)
    np.testing.assert_allclose(j_a, se3.transform_points(Tb, o_b), atol=1e-9)
    # a general motion is not a fixed-joint one
    assert np.ptp(se3.transform_points(Ta, o_a), axis=0).max() > 0.1


def test_overlap_shares_one_world(tmp_path: Path) -> None:
    Ta, Tb, _, truth = _load(write_scenario(tmp_path, "overlap", seed=2))
    np.testing.assert_allclose(truth["T_wb_wa"], np.eye(4), atol=1e-15)
    o_a, o_b = _arr(truth["joint"]["position_in_a"]), _arr(truth["joint"]["position_in_b"])
    np.testing.assert_allclose(
        se3.transform_points(Ta, o_a), se3.transform_points(Tb, o_b), atol=1e-9
    )


def test_noise_and_scale(tmp_path: Path) -> None:
    clean, *_ = _load(write_scenario(tmp_path / "c", "general", seed=4))
    noisy, _, _, truth = _load(
        write_scenario(
            tmp_path / "n", "general", seed=4, rot_noise_deg=1.0, trans_noise=0.05, mu_a=2.0
        )
    )
    assert truth["scale"]["phi_ba"] == pytest.approx(0.5)
    assert (truth["noise"]["sigma_rot_deg"], truth["noise"]["sigma_trans"]) == (1.0, 0.05)
    # every pose, the first included, is perturbed; translation noise before scaling
    dt = noisy[:, :3, 3] / 2.0 - clean[:, :3, 3]
    assert np.all(np.linalg.norm(dt, axis=1) > 0)
    assert 0.02 < np.std(dt) < 0.09
    ang = se3.rotation_angle_deg(np.einsum("nji,njk->nik", clean[:, :3, :3], noisy[:, :3, :3]))
    assert np.all(ang > 0) and 0.5 < np.median(ang) < 3.0


def test_same_seed_same_files(tmp_path: Path) -> None:
    for name in ("x", "y"):
        write_scenario(tmp_path / name, "fixed_joint", seed=9, rot_noise_deg=0.5)
    for f in ("cam_a.tum", "cam_b.tum"):
        assert (tmp_path / "x" / f).read_bytes() == (tmp_path / "y" / f).read_bytes()


def test_hinge_axis_recorded(tmp_path: Path) -> None:
    Ta, Tb, _, truth = _load(write_scenario(tmp_path, "overlap", seed=1, hinge=True))
    axis = _arr(truth["hinge_axis_in_a"])
    assert np.linalg.norm(axis) == pytest.approx(1.0)
    # the articulation R_a_b(i) R_a_b(0)^T is a rotation about the axis (in A)
    R_ab = np.einsum("nji,njk->nik", Ta[:, :3, :3], Tb[:, :3, :3])
    Q = R_ab @ R_ab[0].T
    rv = se3.rotvec_from_matrix(Q)
    np.testing.assert_allclose(np.cross(rv, axis), 0.0, atol=1e-9)


def test_sample_set_shares_one_rig(tmp_path: Path) -> None:
    written = write_sample_set(tmp_path, seed=7, frames=15)
    names = {"fixed_joint", "overlap", "general", "general_scaled", "fixed_joint_scaled"}
    assert set(written) == names
    truths = {n: _load(tmp_path / n)[3] for n in names}
    for n in names:
        for key in ("position_in_a", "position_in_b"):
            np.testing.assert_array_equal(
                truths[n]["joint"][key], truths["fixed_joint"]["joint"][key]
            )
        assert truths[n]["noise"]["sigma_rot_deg"] == 0.6
        assert truths[n]["noise"]["sigma_trans"] == 0.025
    for n in ("general_scaled", "fixed_joint_scaled"):
        scale = truths[n]["scale"]
        assert (scale["mu_a"], scale["mu_b"]) == (SAMPLE_MU_A, SAMPLE_MU_B)
        assert scale["phi_ba"] == pytest.approx(SAMPLE_MU_B / SAMPLE_MU_A)
        # the same noisy poses as the unscaled twin, translations scaled
        Ta, Tb, _, _ = _load(tmp_path / n)
        Ta0, Tb0, _, _ = _load(tmp_path / n.removesuffix("_scaled"))
        np.testing.assert_allclose(Ta[:, :3, 3], SAMPLE_MU_A * Ta0[:, :3, 3], rtol=1e-12)
        np.testing.assert_allclose(Tb[:, :3, 3], SAMPLE_MU_B * Tb0[:, :3, 3], rtol=1e-12)
        np.testing.assert_allclose(Ta[:, :3, :3], Ta0[:, :3, :3], atol=1e-12)


def test_bad_arguments(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="scenario"):
        write_scenario(tmp_path, "hinge", seed=0)
    with pytest.raises(ValueError, match="scales"):
        write_scenario(tmp_path, "general", seed=0, mu_b=0.0)
    with pytest.raises(ValueError, match="negative"):
        write_scenario(tmp_path, "general", seed=0, trans_noise=-1.0)


def test_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = [str(tmp_path / "one"), "--scenario", "general", "--mu-b", "2", "--frames", "8"]
    assert main(argv) == 0
    _, Tb, _, truth = _load(tmp_path / "one")
    assert Tb.shape[0] == 8 and truth["scale"]["mu_b"] == 2.0
    assert main([str(tmp_path / "set"), "--seed", "1", "--frames", "6"]) == 0
    assert (tmp_path / "set" / "fixed_joint_scaled" / "truth.yaml").is_file()
    assert "general_scaled" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main([str(tmp_path / "bad"), "--hinge"])  # --hinge needs --scenario
