"""rig.yaml: written then read back equal; bad files refused naming the key."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest
import yaml

from acs_cli.core.rig_solve import CameraTrack, estimate_rig
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header
from acs_cli.io.rig import RigArtifact
from acs_cli.stages.rig import rig_artifact
from sample_data_gen.rig_sim import rig_recording


@pytest.fixture(scope="module")
def _solved() -> RigArtifact:
    """One rig solve for the module (seconds of CPU; each test gets its own copy)."""
    rng = np.random.default_rng(20240607)
    rec = rig_recording(rng, 30, sigma_rot_deg=0.2, sigma_trans=0.005, unknown_scale=("cam4",))
    tracks = {
        c: CameraTrack(T, np.ones(30, bool), rec.unknown_scale[c]) for c, T in rec.T_wc_c.items()
    }
    est = estimate_rig(rec.topology, tracks)
    art = rig_artifact(est, "m", ["a warning"])
    return dataclasses.replace(art, header=make_header("rig", {}, "test", {"length": "m"}, {}))


@pytest.fixture
def artifact(_solved: RigArtifact) -> RigArtifact:
    return copy.deepcopy(_solved)


def test_round_trip(artifact: RigArtifact, tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    artifact.save(path)
    back = RigArtifact.load(path)
    assert back.body().keys() == artifact.body().keys()
    for name, cam in artifact.cameras.items():
        got = back.cameras[name]
        np.testing.assert_allclose(got.T_cam_ref, cam.T_cam_ref, atol=1e-12)
        np.testing.assert_allclose(got.translation_std, cam.translation_std)
        assert got.scale == pytest.approx(cam.scale) and got.scale_std == cam.scale_std
    for name, j in artifact.joints.items():
        got_j = back.joints[name]
        assert got_j.type == j.type and got_j.between == j.between
        for c, v in j.axis_in.items():
            np.testing.assert_allclose(got_j.axis_in[c], v)
        assert got_j.wobble_rms_deg == j.wobble_rms_deg
        assert (j.wobble_rms_deg is not None) == (j.type == "hinge")
        assert got_j.angle_range_deg == j.angle_range_deg
        assert (j.angle_range_deg is not None) == (j.type == "hinge")
    assert back.warnings == ["a warning"] and back.source == str(path)
    assert "cam4" in back.summary() and "scale" in back.summary()
    np.testing.assert_allclose(back.T_a_b("cam1", "cam1"), np.eye(4), atol=1e-12)


def test_round_trip_with_bundle_sections(artifact: RigArtifact, tmp_path: Path) -> None:
    from acs_cli.io.joint import BundleSection

    section = BundleSection(
        intrinsics_file="cam1/intrinsics.yaml",
        rms_px=0.21,
        sigma_px=0.15,
        frames=40,
        camera_matrix=np.array([[600.0, 0, 320], [0, 601, 240], [0, 0, 1]]),
        distortion=np.array([-0.2, 0.08, 1e-3, -1e-3, 0.0]),
        intrinsics_std={"fx": 0.2, "fy": 0.2, "cx": 0.1, "cy": 0.1, "k3": 0.0},
    )
    art = dataclasses.replace(artifact, bundle_adjustment={"cam1": section})
    path = tmp_path / "rig.yaml"
    art.save(path)
    back = RigArtifact.load(path)
    got = back.bundle_adjustment["cam1"]
    np.testing.assert_allclose(got.camera_matrix, section.camera_matrix)
    np.testing.assert_allclose(got.distortion, section.distortion)
    assert got.frames == 40 and got.rms_px == pytest.approx(0.21)
    assert "bundle adjustment on the corners of 40 frames" in back.summary()
    doc = yaml.safe_load(path.read_text())
    doc["bundle_adjustment"]["ghost"] = doc["bundle_adjustment"]["cam1"]
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=r"bundle_adjustment\.ghost"):
        RigArtifact.load(path)


@pytest.mark.parametrize(
    ("edit", "key"),
    [
        (
            lambda d: d["cameras"]["cam1"].update(T_cam_ref=[[1, 0], [0, 1]]),
            "cameras.cam1.T_cam_ref",
        ),
        (lambda d: d["cameras"]["cam4"].update(scale=-1.0), "cameras.cam4.scale"),
        (lambda d: d["joints"]["j23"].update(type="slider"), "joints.j23.type"),
        (lambda d: d["joints"]["j23"]["axis_in"].pop("cam3"), "joints.j23.axis_in"),
        (lambda d: d["joints"]["j02"].update(between=["cam0", "cam9"]), "joints.j02.between"),
        (lambda d: d.update(reference={"camera": "camX"}), "reference.camera"),
        (
            lambda d: d["joints"]["j23"].update(angle_range_deg=[5, -5]),
            "joints.j23.angle_range_deg",
        ),
    ],
)
def test_bad_rig_yaml_names_the_key(artifact: RigArtifact, tmp_path: Path, edit, key: str) -> None:
    path = tmp_path / "rig.yaml"
    artifact.save(path)
    doc = yaml.safe_load(path.read_text())
    edit(doc)
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError) as err:
        RigArtifact.load(path)
    assert key in str(err.value) and str(path) in str(err.value)


def test_round_trip_with_a_pose_only_body_and_a_rigid_joints_std(
    artifact: RigArtifact, tmp_path: Path
) -> None:
    """Issue 19: a body without corners (``cameras.<body>.pose_only``: its pose noise and
    the board in its world, with stds) and a rigid joint's ``T_q_p`` with its std."""
    from acs_cli.io.rig import PoseOnlySection

    Z = np.eye(4)
    Z[:3, 3] = [0.7, 0.2, -0.1]
    po = PoseOnlySection(
        frames=29,
        sigma_rotation_deg=0.05,
        sigma_translation=3e-4,
        rms_rotation_deg=0.09,
        rms_translation=5e-4,
        T_world_board={"cam1": Z},
        T_world_board_std={"cam1": (np.array([0.01, 0.02, 0.03]), np.array([1e-4, 2e-4, 3e-4]))},
    )
    rigid = next(j for j in artifact.joints.values() if j.type == "rigid")
    assert rigid.T_q_p is not None  # written for every rigid joint
    std = (np.array([0.1, 0.2, 0.3]), np.array([1e-3, 2e-3, 3e-3]))
    art = dataclasses.replace(
        artifact,
        cameras=artifact.cameras
        | {"cam2": dataclasses.replace(artifact.cameras["cam2"], pose_only=po)},
        joints=artifact.joints | {rigid.name: dataclasses.replace(rigid, T_q_p_std=std)},
    )
    path = tmp_path / "rig.yaml"
    art.save(path)
    back = RigArtifact.load(path)
    got = back.cameras["cam2"].pose_only
    assert got is not None and got.frames == 29
    assert got.sigma_rotation_deg == pytest.approx(0.05)
    np.testing.assert_allclose(got.T_world_board["cam1"], Z)
    np.testing.assert_allclose(got.T_world_board_std["cam1"][1], [1e-4, 2e-4, 3e-4])
    j = back.joints[rigid.name]
    assert j.T_q_p is not None and j.T_q_p_std is not None
    np.testing.assert_allclose(j.T_q_p, rigid.T_q_p, atol=1e-12)
    np.testing.assert_allclose(j.T_q_p_std[0], std[0])
    assert "poses only" in back.summary() and "std" in back.summary()
    doc = yaml.safe_load(path.read_text())
    doc["cameras"]["cam2"]["pose_only"]["T_world_board"]["ghost"] = Z.tolist()
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=r"pose_only\.T_world_board\.ghost"):
        RigArtifact.load(path)


def test_an_artifact_built_from_arrays_saves_and_loads(tmp_path: Path) -> None:
    from acs_cli.stages.rig import rig_artifact
    from sample_data_gen.rig_sim import rig_recording

    rec = rig_recording(np.random.default_rng(0), 30, sigma_rot_deg=0.2, sigma_trans=0.005)
    n = rec.timestamps.size
    tracks = {c: CameraTrack(T, np.ones(n, bool)) for c, T in rec.T_wc_c.items()}
    est = estimate_rig(rec.topology, tracks)
    rig_artifact(est, "m", []).save(tmp_path / "rig.yaml")
    back = RigArtifact.load(tmp_path / "rig.yaml")
    assert set(back.cameras) == set(rec.topology.cameras)
    assert back.header["schema"] == "acscal/rig"


def test_the_uncertainty_section_round_trips(artifact: RigArtifact, tmp_path: Path) -> None:
    """rig.yaml's ``uncertainty`` (issue 20): how the stds were made, written and read back;
    a file without it (older) reads as None."""
    from acs_cli.core.correlated import CorrelatedErrors
    from acs_cli.io.joint import UncertaintySection

    assert artifact.uncertainty is not None and artifact.uncertainty.blocks > 0
    grown = UncertaintySection.of(CorrelatedErrors(12, 600, 3.25, ("joint j01",)))
    art = dataclasses.replace(artifact, uncertainty=grown)
    art.save(tmp_path / "rig.yaml")
    back = RigArtifact.load(tmp_path / "rig.yaml")
    assert back.uncertainty == grown and "grown by the block sandwich" in grown.method
    doc = yaml.safe_load((tmp_path / "rig.yaml").read_text())
    del doc["uncertainty"]
    (tmp_path / "old.yaml").write_text(yaml.safe_dump(doc))
    assert RigArtifact.load(tmp_path / "old.yaml").uncertainty is None
    doc["uncertainty"] = {"blocks": "many"}
    (tmp_path / "bad.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=r"uncertainty\.blocks"):
        RigArtifact.load(tmp_path / "bad.yaml")
