"""Every export loaded by its consumer's own reader (or its documented rules).

OpenCV's ``cv2.FileStorage``, evo's TUM reader, Kalibr's camchain rules and ROS's
camera_info schema (the last two in ``tests/export_consumers.py``).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from export_consumers import ConsumerError, read_kalibr_camchain, read_ros_camera_info
from scipy.spatial.transform import Rotation

from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.export import opencv_camera_values, ros_camera_info_text, write_opencv_yaml
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.rig import RigArtifact, RigCameraResult, RigJointResult
from acs_cli.io.rig_export import (
    kalibr_camchain_from_pair,
    kalibr_camchain_from_rig,
    rig_in_metres,
)
from acs_cli.io.trajectory import write_tum
from sample_data_gen.rig_sim import RigRecording, rig_recording

N_COEFFS = {"pinhole": 5, "rational": 8, "fisheye": 4}


def _intrinsics(i: int, model: str = "pinhole") -> IntrinsicsArtifact:
    K = np.array([[600.0 + i, 0, 330.5], [0, 601.0 + i, 250.25], [0, 0, 1]])
    D = np.zeros(N_COEFFS[model])
    D[:4] = [-0.2 + 0.01 * i, 0.03, 2e-4, -1e-4]
    return IntrinsicsArtifact(model=model, image_size=(752, 480), camera_matrix=K, distortion=D)


def _random_T(rng: np.random.Generator) -> np.ndarray:
    R = Rotation.random(random_state=rng).as_matrix()
    return np.asarray(se3.transforms_from_rt(R, rng.normal(size=3))).reshape(4, 4)


def _rig(rec: RigRecording) -> RigArtifact:
    """The recording's true rig (metres) as a RigArtifact."""
    T = rec.T_cam_ref(0)
    cameras = {
        c: RigCameraResult(c, T[c], np.zeros(3), np.full(3, 1e-3)) for c in rec.topology.cameras
    }
    joints = {}
    for name, e in rec.edges.items():
        p, q = e.between
        pos = {} if e.type == "rigid" else {p: e.o_p, q: e.o_q}
        joints[name] = RigJointResult(name, e.type, e.between, position_in=pos, residual_rms=0.01)
    return RigArtifact(rec.topology.reference, 0, "m", cameras, joints)


# ------------------------------------------------------------------------ Kalibr


def test_the_kalibr_rules_refuse_what_kalibr_refuses(tmp_path: Path) -> None:
    """The issue's camchain (rostopic and T_cn_cnm1 only) stops Kalibr; so do bad fields."""
    path = tmp_path / "camchain.yaml"
    old = {"cam0": {"rostopic": "/a"}, "cam1": {"rostopic": "/b", "T_cn_cnm1": np.eye(4).tolist()}}
    path.write_text(yaml.safe_dump(old))
    with pytest.raises(ConsumerError, match="Field 'camera_model' missing"):
        read_kalibr_camchain(path)
    intr = {"a": _intrinsics(0), "b": _intrinsics(1)}
    good = yaml.safe_load(kalibr_camchain_from_pair(np.eye(4), intr, names=("a", "b")))
    for key, value, match in (
        ("intrinsics", [600, 601, 330.5, 250.25], "focalLength"),
        ("resolution", [752.0, 480.0], "resolution"),
        ("distortion_coeffs", [0.1] * 5, "radtan"),
        ("cam_overlaps", [2], "out-of-range"),
        ("T_cn_cnm1", (2 * np.eye(4)).tolist(), "rigid"),
        ("T_cn_cnm1", None, "Field 'T_cn_cnm1' missing"),
    ):
        doc = yaml.safe_load(yaml.safe_dump(good))
        if value is None:
            del doc["cam1"][key]
        else:
            doc["cam1"][key] = value
        path.write_text(yaml.safe_dump(doc))
        with pytest.raises(ConsumerError, match=match):
            read_kalibr_camchain(path)


def test_a_pair_camchain_reads_in_kalibr(tmp_path: Path, rng: np.random.Generator) -> None:
    T_b_a = _random_T(rng)
    intr = {"left": _intrinsics(0), "right": _intrinsics(1, "fisheye")}
    text = kalibr_camchain_from_pair(
        T_b_a, intr, names=("left", "right"), reference=4, overlap=True, notes=["WARNING: x"]
    )
    path = tmp_path / "camchain.yaml"
    path.write_text(text)
    cam0, cam1 = read_kalibr_camchain(path)
    # Kalibr's T_cn_cnm1 = T_c1_c0 takes cam0's coordinates into cam1's: p_b = T_b_a p_a
    p_a = np.array([0.3, -0.2, 2.0, 1.0])
    np.testing.assert_allclose(cam1["T_cn_cnm1"] @ p_a, T_b_a @ p_a, atol=1e-12)
    assert cam0["intrinsics"] == [600.0, 601.0, 330.5, 250.25]
    assert (cam0["distortion_model"], cam1["distortion_model"]) == ("radtan", "equidistant")
    assert cam0["distortion_coeffs"] == pytest.approx([-0.2, 0.03, 2e-4, -1e-4])
    assert cam1["distortion_coeffs"] == pytest.approx([-0.19, 0.03, 2e-4, -1e-4])
    assert cam0["resolution"] == [752, 480] and cam1["rostopic"] == "/right/image_raw"
    assert (cam0["cam_overlaps"], cam1["cam_overlaps"]) == ([1], [0])
    assert "reference instant only (paired frame 4)" in text and "# WARNING: x" in text
    no_overlap = yaml.safe_load(kalibr_camchain_from_pair(T_b_a, intr, names=("left", "right")))
    assert no_overlap["cam0"]["cam_overlaps"] == no_overlap["cam1"]["cam_overlaps"] == []


def test_kalibr_has_no_rational_model() -> None:
    rational = _intrinsics(1, "rational")
    rational.distortion[6] = 0.02
    with pytest.raises(InputError, match="camera b: Kalibr's radtan model holds k1 k2 p1 p2"):
        kalibr_camchain_from_pair(np.eye(4), {"a": _intrinsics(0), "b": rational}, names=("a", "b"))
    with pytest.raises(InputError, match="missing for b"):
        kalibr_camchain_from_pair(np.eye(4), {"a": _intrinsics(0)}, names=("a", "b"))


def test_a_rig_camchain_in_metres_reads_in_kalibr(tmp_path: Path, rng: np.random.Generator) -> None:
    rec = rig_recording(rng, 10, unknown_scale=("cam4",))
    rig = _rig(rec)
    cams = list(rig.cameras)
    in_mm = rig_in_metres(rig, 1000.0)  # the same rig, lengths in mm
    assert in_mm.length_unit == "m"
    back = rig_in_metres(in_mm, 1e-3)
    for c in cams:
        np.testing.assert_allclose(back.cameras[c].T_cam_ref, rig.cameras[c].T_cam_ref, atol=1e-12)
        np.testing.assert_allclose(in_mm.cameras[c].translation_std, np.full(3, 1.0))
    j = next(j for j in rig.joints.values() if j.position_in)
    first = j.between[0]
    np.testing.assert_allclose(in_mm.joints[j.name].position_in[first], 1e3 * j.position_in[first])
    assert in_mm.joints[j.name].residual_rms == pytest.approx(10.0)
    path = tmp_path / "camchain.yaml"
    path.write_text(kalibr_camchain_from_rig(rig, {c: _intrinsics(i) for i, c in enumerate(cams)}))
    chain = read_kalibr_camchain(path)
    assert len(chain) == len(cams) == 5
    T_c_0 = np.eye(4)
    for i, cam in enumerate(chain):
        if i:
            T_c_0 = cam["T_cn_cnm1"] @ T_c_0
        T_ref = rig.cameras[cams[i]].T_cam_ref @ se3.invert_transforms(
            rig.cameras[cams[0]].T_cam_ref
        )
        np.testing.assert_allclose(T_c_0, T_ref, atol=1e-9)


# ------------------------------------------------------------------------ ROS


@pytest.mark.parametrize(
    ("model", "ros_model"),
    [("pinhole", "plumb_bob"), ("rational", "rational_polynomial"), ("fisheye", "equidistant")],
)
def test_ros_camera_info_schema(tmp_path: Path, model: str, ros_model: str) -> None:
    intr = _intrinsics(2, model)
    path = tmp_path / "left.yaml"
    path.write_text(
        ros_camera_info_text(
            intr.camera_matrix, intr.distortion, intr.image_size, model, "left", comments=["x"]
        )
    )
    msg = read_ros_camera_info(path)
    assert (msg["width"], msg["height"], msg["camera_name"]) == (752, 480, "left")
    assert msg["distortion_model"] == ros_model
    np.testing.assert_array_equal(msg["D"], intr.distortion)
    np.testing.assert_array_equal(msg["K"].reshape(3, 3), intr.camera_matrix)
    np.testing.assert_array_equal(msg["R"].reshape(3, 3), np.eye(3))
    np.testing.assert_array_equal(msg["P"].reshape(3, 4)[:, :3], intr.camera_matrix)
    np.testing.assert_array_equal(msg["P"].reshape(3, 4)[:, 3], 0.0)


def test_ros_camera_info_refusals(tmp_path: Path) -> None:
    intr = _intrinsics(0)
    args = (intr.camera_matrix, intr.distortion, intr.image_size, "pinhole")
    with pytest.raises(InputError, match="letters, digits and underscores"):
        ros_camera_info_text(*args, "left/cam")
    with pytest.raises(InputError, match="5 finite coefficients"):
        ros_camera_info_text(intr.camera_matrix, intr.distortion[:4], (752, 480), "pinhole", "a")
    # the schema catches a D of the wrong length for its model
    doc = yaml.safe_load(ros_camera_info_text(*args, "left"))
    doc["distortion_model"] = "equidistant"
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConsumerError, match="equidistant has 4"):
        read_ros_camera_info(path)


# ------------------------------------------------------------------------ OpenCV


@pytest.mark.parametrize("suffix", [".yaml", ".xml"])
def test_opencv_camera_file_reads_in_filestorage(
    tmp_path: Path, rng: np.random.Generator, suffix: str
) -> None:
    T_b_a = _random_T(rng)
    a, b = _intrinsics(0), _intrinsics(1, "rational")
    path = tmp_path / f"stereo{suffix}"
    write_opencv_yaml(
        path,
        {
            "R": T_b_a[:3, :3],
            "T": T_b_a[:3, 3:4],
            "cam_a": {
                "camera_name": "left",
                **opencv_camera_values(a.camera_matrix, a.distortion, a.image_size, a.model),
            },
            "cam_b": opencv_camera_values(b.camera_matrix, b.distortion, b.image_size, b.model),
        },
        comments=["WARNING: poorly determined"],
    )
    if suffix == ".yaml":
        assert "# WARNING: poorly determined" in path.read_text()
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    try:
        R, T = fs.getNode("R").mat(), fs.getNode("T").mat()
        p_a = np.array([0.1, 0.2, 1.5])
        np.testing.assert_allclose(R @ p_a + T.ravel(), (T_b_a @ np.append(p_a, 1))[:3])
        node = fs.getNode("cam_a")
        assert node.isMap() and node.getNode("camera_name").string() == "left"
        np.testing.assert_array_equal(node.getNode("camera_matrix").mat(), a.camera_matrix)
        assert int(node.getNode("image_width").real()) == 752
        assert int(node.getNode("image_height").real()) == 480
        D = fs.getNode("cam_b").getNode("distortion_coefficients").mat()
        assert D.shape == (1, 8)
        np.testing.assert_array_equal(D.ravel(), b.distortion)
        assert fs.getNode("cam_b").getNode("model").string() == "rational"
    finally:
        fs.release()
    with pytest.raises(TypeError, match="one level"):
        write_opencv_yaml(tmp_path / "deep.yaml", {"a": {"b": {"c": 1}}})


# ------------------------------------------------------------------------ evo (TUM)


@pytest.mark.parametrize("kind", ["seconds", "nanoseconds", "frame numbers"])
def test_tum_files_read_in_evo(tmp_path: Path, rng: np.random.Generator, kind: str) -> None:
    from evo.tools import file_interface

    n = 7
    T = np.stack([_random_T(rng) for _ in range(n)])
    path = tmp_path / "poses.tum"
    if kind == "seconds":
        t = 1623456789.0 + 0.05 * np.arange(n)
        write_tum(path, t, T)
    elif kind == "nanoseconds":
        ns = 1403636579763555584 + 50_000_000 * np.arange(n, dtype=np.int64)
        t = ns / 1e9
        write_tum(path, t, T, timestamps_ns=ns)
    else:
        t = np.arange(n, dtype=float) * 10
        write_tum(path, t, T, note="times are frame numbers")
    traj = file_interface.read_tum_trajectory_file(str(path))
    assert traj.num_poses == n
    np.testing.assert_allclose(traj.timestamps, t, rtol=0, atol=1e-6)
    np.testing.assert_allclose(traj.positions_xyz, T[:, :3, 3], atol=1e-12)
    for i, pose in enumerate(traj.poses_se3):  # evo's SE(3) of each row: T_world_cam
        np.testing.assert_allclose(pose, T[i], atol=1e-12)
