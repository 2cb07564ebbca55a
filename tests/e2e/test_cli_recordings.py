"""``acscal run`` over a rig config of several recordings and shared worlds (issue 19):
motion capture of a leg (a hip trial and a knee trial, one lab world each)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.io.rig import RigArtifact
from acs_cli.io.trajectory import write_tum
from sample_data_gen import mocap_sim as M

CONFIG = """\
schema: acscal/run-config
schema_version: 2
output: out/
reference: {camera: pelvis, recording: hip, frame: 0}
recordings:
  hip:
    world: shared
    cameras:
      pelvis: {poses: hip_pelvis.tum}
      femur: {poses: hip_femur.tum}
  knee:
    world: shared
    cameras:
      femur: {poses: knee_femur.tum}
      tibia: {poses: knee_tibia.tum}
joints:
  hip: {between: [pelvis, femur], type: ball}
  knee: {between: [femur, tibia], type: hinge}
"""


@pytest.fixture(scope="module")
def leg(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("leg")
    rng = np.random.default_rng(7)
    for name, trial in (("hip", M.hip_trial(rng)), ("knee", M.knee_trial(rng))):
        for body, T in trial.measured.items():
            write_tum(root / f"{name}_{body}.tum", trial.times, T)
    (root / "config.yaml").write_text(CONFIG)
    return root


def test_a_leg_from_two_trials(leg: Path) -> None:
    res = acscal("run", leg / "config.yaml")
    assert res.returncode == 0, res.stderr
    rig = RigArtifact.load(leg / "out" / "rig.yaml")
    hip = rig.joints["hip"]
    assert np.linalg.norm(hip.position_in["pelvis"] - M.HIP_IN_PELVIS) < 0.003
    u = M.KNEE_AXIS_IN_FEMUR
    assert abs(float(rig.joints["knee"].axis_in["femur"] @ u)) > np.cos(np.radians(0.5))
    # the tibia is not in the reference recording: no pose there, said so in the file
    assert rig.cameras["tibia"].T_cam_ref is None
    doc = yaml.safe_load((leg / "out" / "rig.yaml").read_text())
    assert doc["cameras"]["tibia"]["T_cam_ref"] is None
    assert doc["recordings"]["hip"]["world"] == "shared"
    assert doc["recordings"]["knee"]["worlds"]["knee"]["tied"] is False
    assert doc["recordings"]["hip"]["frames"] == 300
    # trajectories of the reference recording only
    traj = sorted(f.name for f in (leg / "out" / "trajectories").iterdir())
    assert traj == ["femur.tum", "hip.tum", "pelvis.tum"]
    assert "no bundle adjustment" not in res.stderr  # poses only: nothing to say
    again = acscal("run", leg / "config.yaml")
    assert again.returncode == 0 and "rig: skipped" in again.stdout, again.stdout


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (("recording: hip", "recording: run"), "reference.recording"),
        (("camera: pelvis, recording", "camera: tibia, recording"), "reference.camera"),
        (
            ("tibia: {poses: knee_tibia.tum}", "tibia: {poses: knee_tibia.tum, scale: unknown}"),
            None,
        ),
        (
            ("femur: {poses: knee_femur.tum}", "femur: {poses: knee_femur.tum, model: fisheye}"),
            "recordings.knee.cameras.femur.model",
        ),
        (
            (
                "  knee:\n    world: shared\n    cameras:\n      femur: {poses: knee_femur.tum}\n",
                "  knee:\n    world: shared\n    cameras:\n",
            ),
            "joints.knee",
        ),
        (
            (
                "    world: shared\n    cameras:\n      pelvis",
                "    world: one\n    cameras:\n      pelvis",
            ),
            "recordings.hip.world",
        ),
    ],
)
def test_bad_recordings_exit_2_naming_the_key(
    leg: Path, tmp_path: Path, edit: tuple[str, str], key: str | None
) -> None:
    text = CONFIG.replace(*edit)
    assert text != CONFIG
    for f in leg.glob("*.tum"):
        (tmp_path / f.name).symlink_to(f)
    (tmp_path / "config.yaml").write_text(text)
    res = acscal("run", tmp_path / "config.yaml")
    assert res.returncode == 2, res.stdout + res.stderr
    lines = [ln for ln in res.stderr.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, res.stderr
    if key is not None:
        assert key in res.stderr
    assert not (tmp_path / "out" / "rig.yaml").exists()


def test_the_papers_scenario_2_as_one_config(tmp_path: Path) -> None:
    # a fixed-joint recording (the joint held still, each camera on its own board) and a
    # general-motion recording, in one config: Algorithm II's prior, then the rig solve
    from sample_data_gen import acs_sim

    rng = np.random.default_rng(11)
    rig = acs_sim.make_rig(rng)
    fixed = acs_sim.fixed_joint_sequence(rng, rig, 30)
    general = acs_sim.general_sequence(rng, rig, 40)
    for name, seq in (("fixed", fixed), ("general", general)):
        for cam, T in (("a", seq.T_wa_a), ("b", seq.T_wb_b)):
            write_tum(tmp_path / f"{name}_{cam}.tum", seq.timestamps,
                      acs_sim.add_pose_noise(rng, T, 0.3, 0.01))  # fmt: skip
    (tmp_path / "config.yaml").write_text(
        "schema_version: 2\noutput: out/\nreference: {camera: a, recording: general}\n"
        "recordings:\n"
        "  fixed:\n    fixed_joints: [j]\n"
        "    cameras: {a: {poses: fixed_a.tum}, b: {poses: fixed_b.tum}}\n"
        "  general:\n    cameras: {a: {poses: general_a.tum}, b: {poses: general_b.tum}}\n"
        "joints:\n  j: {between: [a, b], type: ball}\n"
    )
    res = acscal("run", tmp_path / "config.yaml")
    assert res.returncode == 0, res.stderr
    r = RigArtifact.load(tmp_path / "out" / "rig.yaml")
    assert np.linalg.norm(r.joints["j"].position_in["a"] - rig.o_a) < 0.05
    assert r.joints["j"].frames_used + r.joints["j"].frames_rejected == 40
    T = r.posed("b")
    assert np.linalg.norm(T[:3, 3] - general.T_b_a(0)[:3, 3]) < 0.1


def test_the_reference_in_the_second_recording_and_its_trajectories(
    leg: Path, tmp_path: Path
) -> None:
    # review findings: rig.yaml gives the reference as the config does (a frame of its
    # recording), and acscal trajectory --rig reads such a rig.yaml
    for f in leg.glob("*.tum"):
        (tmp_path / f.name).symlink_to(f)
    (tmp_path / "config.yaml").write_text(
        CONFIG.replace(
            "{camera: pelvis, recording: hip, frame: 0}",
            "{camera: femur, recording: knee, frame: 5}",
        )
    )
    res = acscal("run", tmp_path / "config.yaml")
    assert res.returncode == 0, res.stderr
    doc = yaml.safe_load((tmp_path / "out" / "rig.yaml").read_text())
    assert doc["reference"] == {"camera": "femur", "frame": 5, "recording": "knee"}
    assert doc["cameras"]["pelvis"]["T_cam_ref"] is None
    traj = sorted(f.name for f in (tmp_path / "out" / "trajectories").iterdir())
    assert traj == ["femur.tum", "knee.tum", "tibia.tum"]
    res = acscal("trajectory", "--rig", tmp_path / "out" / "rig.yaml", "-o", tmp_path / "t")
    assert res.returncode == 0, res.stderr
    assert sorted(f.name for f in (tmp_path / "t").iterdir()) == sorted([*traj, "angles.csv"])


def test_each_recording_estimates_its_own_clocks(tmp_path: Path) -> None:
    """Issue 19: ``estimate_time_offset`` with several recordings (it was refused): each
    recording's clock offsets are estimated on its own, from the camera nearest the
    reference (cam0 in the hip trial, cam1 in the knee trial), and reported per recording."""
    from sample_data_gen.rig_sim import make_edges, rig_recording

    joints = (("hip", ("cam0", "cam1"), "ball"), ("knee", ("cam1", "cam2"), "hinge"))
    edges = make_edges(np.random.default_rng(0), joints)
    trials = {
        "hip": ({"cam1": 0.013}, ("cam0", "cam1")),
        "knee": ({"cam2": -0.021}, ("cam1", "cam2")),
    }
    for seed, (name, (late, cams)) in enumerate(trials.items()):
        rec = rig_recording(
            np.random.default_rng(seed + 1), 150, joints=joints, edges=edges, smooth=True,
            time_offsets=late, sigma_rot_deg=0.1, sigma_trans=0.002,
        )  # fmt: skip
        for c in cams:
            write_tum(tmp_path / f"{name}_{c}.tum", rec.timestamps, rec.T_wc_c[c])
    cfg = tmp_path / "rig.yaml"
    cfg.write_text(
        "schema_version: 2\noutput: out\nestimate_time_offset: true\nmax_offset: 0.1\n"
        "reference: {camera: cam0, recording: hip, frame: 0}\n"
        "recordings:\n"
        "  hip:\n    cameras: {cam0: {poses: hip_cam0.tum}, cam1: {poses: hip_cam1.tum}}\n"
        "  knee:\n    cameras: {cam1: {poses: knee_cam1.tum}, cam2: {poses: knee_cam2.tum}}\n"
        "joints:\n  hip: {between: [cam0, cam1], type: ball}\n"
        "  knee: {between: [cam1, cam2], type: hinge}\n",
        encoding="utf-8",
    )
    res = acscal("run", cfg, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    rig = RigArtifact.load(tmp_path / "out" / "rig.yaml")
    for name, clock, cam, truth in (
        ("hip", "cam0", "cam1", 0.013),
        ("knee", "cam1", "cam2", -0.021),
    ):
        r = rig.recordings[name]
        assert r.clock == clock
        offset, std = r.time_offsets[cam]
        assert abs(offset - truth) < max(4 * std, 1e-4), (name, offset, std)
    for name, (p, q), _ in joints:
        truth_p, truth_q = edges[name].o_p, edges[name].o_q
        j = rig.joints[name]
        for c, o in ((p, truth_p), (q, truth_q)):
            err = float(np.linalg.norm(j.position_in[c] - o))
            assert err < 5 * np.linalg.norm(j.position_std_in[c]) + 1e-4, (name, c, err)
