"""Exports of a rig: URDF (kinematics recomposed from the XML) and Kalibr camchain."""

from __future__ import annotations

import dataclasses
import io
import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from export_consumers import check_kalibr_camchain
from scipy.spatial.transform import Rotation

from acs_cli.core import se3
from acs_cli.core.angles import hinge_angle_range_deg
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.rig import RigArtifact, RigCameraResult, RigJointResult
from acs_cli.io.rig_export import (
    kalibr_camchain_from_rig,
    matrix_from_urdf_rpy,
    urdf_from_rig,
    urdf_rpy_from_matrix,
    write_rig_export,
)
from sample_data_gen.rig_sim import RigRecording, rig_recording

TOL = 1e-9


# ------------------------------------------------------------------------ helpers


def rig_from_recording(
    rec: RigRecording, reference: str | None = None, frame: int = 0
) -> RigArtifact:
    """The true rig of a recording as a RigArtifact (metres), ``reference`` its reference."""
    T = rec.T_cam_ref(frame)
    ref = reference or rec.topology.reference
    T_ref_old = se3.invert_transforms(T[ref])  # re-express against the new reference
    scale = rec.scale()
    cameras = {
        c: RigCameraResult(
            name=c,
            T_cam_ref=T[c] @ T_ref_old,
            rotation_std_deg=np.zeros(3),
            translation_std=np.zeros(3),
            unknown_scale=rec.unknown_scale[c],
            scale=scale[c],
        )
        for c in rec.topology.cameras
    }
    joints = {}
    for name, e in rec.edges.items():
        p, q = e.between
        pos = {} if e.type == "rigid" else {p: e.o_p, q: e.o_q}
        axis: dict[str, Any] = {}
        if e.type == "hinge":
            assert e.axis_p is not None and e.axis_q is not None
            axis = {p: e.axis_p, q: e.axis_q}
        joints[name] = RigJointResult(name, e.type, e.between, position_in=pos, axis_in=axis)
    return RigArtifact(ref, frame, "m", cameras, joints)


def _floats(text: str | None) -> np.ndarray:
    assert text is not None
    return np.array([float(v) for v in text.split()])


def _urdf_kinematics(text: str) -> tuple[str, dict[str, dict[str, Any]]]:
    """The root link and, per child link, its joint (type, parent, origin, axis, limits)."""
    root = ET.fromstring(text)
    assert root.tag == "robot"
    links = [el.get("name") for el in root.findall("link")]
    assert len(links) == len(set(links))
    joints: dict[str, dict[str, Any]] = {}
    names = []
    for el in root.findall("joint"):
        names.append(el.get("name"))
        origin = el.find("origin")
        assert origin is not None
        T = se3.transforms_from_rt(
            matrix_from_urdf_rpy(_floats(origin.get("rpy"))), _floats(origin.get("xyz"))
        )
        parent, child = el.find("parent"), el.find("child")
        assert parent is not None and child is not None
        axis = el.find("axis")
        child_name = child.get("link")
        assert child_name in links and parent.get("link") in links
        assert child_name not in joints, "a link with two parents"
        joints[str(child_name)] = {
            "name": el.get("name"),
            "type": el.get("type"),
            "parent": parent.get("link"),
            "origin": T,
            "axis": None if axis is None else _floats(axis.get("xyz")),
            "limit": el.find("limit"),
        }
    assert len(names) == len(set(names))
    roots = [n for n in links if n not in joints]
    assert len(roots) == 1
    return str(roots[0]), joints


def _forward(
    joints: dict[str, dict[str, Any]], root: str, angles: dict[str, float] | None = None
) -> dict[str, np.ndarray]:
    """``T_root_link`` of every link at joint angles (radians, by joint name; 0 default)."""
    angles = angles or {}
    out = {root: np.eye(4)}

    def pose(link: str) -> np.ndarray:
        if link not in out:
            j = joints[link]
            T = j["origin"]
            if j["type"] == "revolute":
                R = se3.matrix_from_rotvec(angles.get(j["name"], 0.0) * j["axis"])
                T = T @ se3.transforms_from_rt(R, np.zeros(3))
            else:
                assert j["type"] == "fixed"
            out[link] = pose(j["parent"]) @ T
        return out[link]

    for link in joints:
        pose(link)
    return out


def _check_poses(rig: RigArtifact, T_root: dict[str, np.ndarray]) -> None:
    """Every camera link's pose at zero angles reproduces ``T_cam_ref`` (pairwise)."""
    ref = rig.reference_camera
    for c in rig.cameras:
        T_c_ref = se3.invert_transforms(T_root[c]) @ T_root[ref]
        np.testing.assert_allclose(T_c_ref, rig.cameras[c].T_cam_ref, atol=TOL, rtol=0)
        for d in rig.cameras:
            T_c_d = se3.invert_transforms(T_root[c]) @ T_root[d]
            np.testing.assert_allclose(T_c_d, rig.T_a_b(c, d), atol=TOL, rtol=0)


@pytest.fixture
def rec(rng: np.random.Generator) -> RigRecording:
    return rig_recording(rng, 20, unknown_scale=("cam4",))


# ------------------------------------------------------------------------ URDF


def test_rpy_round_trip_gimbal_lock(rng: np.random.Generator) -> None:
    Rs = list(Rotation.random(200, random_state=rng).as_matrix())
    for pitch in (math.pi / 2, -math.pi / 2, math.pi / 2 - 1e-9, -math.pi / 2 + 1e-13):
        for _ in range(5):
            r, y = rng.uniform(-math.pi, math.pi, size=2)
            Rs.append(matrix_from_urdf_rpy([r, pitch, y]))
    Rs += [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0])]
    for R in Rs:
        rpy = urdf_rpy_from_matrix(R)
        np.testing.assert_allclose(matrix_from_urdf_rpy(rpy), R, atol=1e-14)
        assert -math.pi / 2 <= rpy[1] <= math.pi / 2
    # URDF's convention: fixed-axis roll, pitch, yaw = Rz(yaw) Ry(pitch) Rx(roll)
    expect = Rotation.from_euler("ZYX", [0.3, -0.2, 0.1]).as_matrix()
    np.testing.assert_allclose(matrix_from_urdf_rpy([0.1, -0.2, 0.3]), expect, atol=1e-15)
    np.testing.assert_allclose(
        matrix_from_urdf_rpy([0.1, -0.2, 0.3]),
        se3.matrix_from_rpy_deg(np.degrees([0.1, -0.2, 0.3])),
        atol=1e-14,
    )


@pytest.mark.parametrize("reference", ["cam0", "cam2", "cam4", "cam1 reversed"])
def test_urdf_zero_angles_reproduce_the_rig(rec: RigRecording, reference: str) -> None:
    rig = rig_from_recording(rec, reference.split()[0])
    if reference.endswith("reversed"):  # bodies named after cam1 and cam4, entered by others
        cams = dict(reversed(rig.cameras.items()))
        rig = RigArtifact(rig.reference_camera, 0, "m", cams, rig.joints)
    text = urdf_from_rig(rig, robot_name="my_rig")
    assert text.startswith('<?xml version="1.0"?>\n<robot name="my_rig">')
    root, joints = _urdf_kinematics(text)
    # the root is the reference camera's body, named after its first camera
    first = {"cam0": "cam0", "cam2": "cam2", "cam4": "cam3", "cam1 reversed": "cam1"}[reference]
    assert root == f"body_{first}"
    _check_poses(rig, _forward(joints, root))
    # one body per rigid group; the camera links hang from their body by fixed joints
    b01, b34 = ("body_cam1", "body_cam4") if "reversed" in reference else ("body_cam0", "body_cam3")
    assert {c: joints[c]["parent"] for c in rig.cameras} == {
        "cam0": b01,
        "cam1": b01,
        "cam2": "body_cam2",
        "cam3": b34,
        "cam4": b34,
    }
    assert all(joints[c]["type"] == "fixed" for c in rig.cameras)
    kinds = {j["name"]: j["type"] for j in joints.values()}
    assert kinds["j23"] == "revolute"
    assert kinds["j02_x"] == kinds["j02_y"] == kinds["j02_z"] == "revolute"
    # a rigid edge becomes the fixed joint of the camera it reaches inside its body
    assert {"r01", "r34"} <= set(kinds)
    assert kinds["r01"] == kinds["r34"] == "fixed"
    for j in joints.values():
        if j["type"] == "revolute":
            lim = j["limit"]
            assert lim is not None
            assert float(lim.get("lower")) == -math.pi and float(lim.get("upper")) == math.pi
            assert float(lim.get("effort")) > 0 and float(lim.get("velocity")) > 0
            assert np.linalg.norm(j["axis"]) == pytest.approx(1.0, abs=1e-12)
    assert "not calibrated" in text and "massless" in text and "three revolute" in text


def _sim_edge(rec: RigRecording, name: str, Q: np.ndarray) -> np.ndarray:
    """``T_p_q`` of an edge articulated by ``Q`` (in p's frame) on top of frame 0's."""
    e = rec.edges[name]
    p, q = e.between
    T_p_q0 = se3.invert_transforms(rec.T_W_c[p][0]) @ rec.T_W_c[q][0]
    Q0 = T_p_q0[:3, :3] @ e.R0.T  # the articulation at frame 0
    return e.T_p_q((Q @ Q0)[None])[0]


def test_urdf_joints_articulate_like_the_rig(rec: RigRecording, rng: np.random.Generator) -> None:
    rig = rig_from_recording(rec)
    root, joints = _urdf_kinematics(urdf_from_rig(rig))
    e23 = rec.edges["j23"]
    assert e23.axis_p is not None
    for theta in (-2.5, -0.4, 0.7, 3.0):
        T = _forward(joints, root, {"j23": theta})
        got = se3.invert_transforms(T["cam2"]) @ T["cam3"]
        want = _sim_edge(rec, "j23", se3.matrix_from_rotvec(theta * e23.axis_p))
        np.testing.assert_allclose(got, want, atol=TOL, rtol=0)
        # cam4 rides rigidly with cam3
        np.testing.assert_allclose(
            se3.invert_transforms(T["cam3"]) @ T["cam4"], rig.T_a_b("cam3", "cam4"), atol=TOL
        )
    # the ball: any rotation Q about the centre (in cam0's frame) through the three revolutes
    body2 = _forward(joints, root)["body_cam2"]  # T_cam0_body2 at zero (cam0 is the root)
    R_p_C = body2[:3, :3]
    e02 = rec.edges["j02"]
    for Q in Rotation.random(5, random_state=rng).as_matrix():
        a, b, c = Rotation.from_matrix(R_p_C.T @ Q @ R_p_C).as_euler("XYZ")
        T = _forward(joints, root, {"j02_x": a, "j02_y": b, "j02_z": c})
        got = se3.invert_transforms(T["cam0"]) @ T["cam2"]
        np.testing.assert_allclose(got, _sim_edge(rec, "j02", Q), atol=TOL, rtol=0)
        np.testing.assert_allclose(se3.transform_points(got, e02.o_q), e02.o_p, atol=TOL, rtol=0)
    # the ball's centre is the origin of the child body's frame
    np.testing.assert_allclose(body2[:3, 3], e02.o_p, atol=TOL)


@pytest.mark.parametrize("reference", ["cam0", "cam4"])
def test_urdf_hinge_limits_hold_the_observed_angles(rec: RigRecording, reference: str) -> None:
    """Limits from rig.yaml's angle range plus the margin, in the URDF joint's own sense:
    from cam0 the hinge hangs cam3 from cam2 (as ``between``), from cam4 cam2 from cam3
    (reversed). Every frame's relative pose is reached at an angle within the limits less
    the margin, and the extreme frames at the limits less the margin."""
    rig = rig_from_recording(rec, reference)
    e = rec.edges["j23"]
    assert e.axis_p is not None
    R = {c: rec.T_W_c[c][:, :3, :3] for c in ("cam2", "cam3")}
    R0 = rig.cameras["cam2"].T_cam_ref[:3, :3] @ rig.cameras["cam3"].T_cam_ref[:3, :3].T
    span = hinge_angle_range_deg(R["cam2"], R["cam3"], R0, e.axis_p)
    joint = dataclasses.replace(rig.joints["j23"], angle_range_deg=span)
    rig = dataclasses.replace(rig, joints={**rig.joints, "j23": joint})
    root, joints = _urdf_kinematics(urdf_from_rig(rig, limit_margin_deg=7.5))
    j = next(v for v in joints.values() if v["name"] == "j23")
    lower, upper = float(j["limit"].get("lower")), float(j["limit"].get("upper"))
    assert upper - lower == pytest.approx(math.radians(span[1] - span[0] + 15.0), abs=1e-6)
    # each frame's articulation at its angle: the twist about the URDF axis
    T_rel = se3.invert_transforms(rec.T_W_c["cam2"]) @ rec.T_W_c["cam3"]
    grid = np.radians(np.arange(-200.0, 200.0, 0.5))
    T_at = np.stack(
        [
            se3.invert_transforms(T["cam2"]) @ T["cam3"]
            for T in (_forward(joints, root, {"j23": a}) for a in grid)
        ]
    )
    gap = np.linalg.norm(T_at[None] - T_rel[:, None], axis=(2, 3))  # (frames, angles)
    assert float(np.max(np.min(gap, axis=1))) < 0.02  # every frame's pose is on the hinge
    reached = grid[np.argmin(gap, axis=1)]
    assert min(reached) == pytest.approx(lower + math.radians(7.5), abs=math.radians(0.5))
    assert max(reached) == pytest.approx(upper - math.radians(7.5), abs=math.radians(0.5))


def test_urdf_hinge_axis_and_point(rec: RigRecording) -> None:
    rig = rig_from_recording(rec)
    root, joints = _urdf_kinematics(urdf_from_rig(rig))
    T = _forward(joints, root)
    e = rec.edges["j23"]
    assert e.axis_q is not None
    j = joints["body_cam3"]
    assert j["name"] == "j23" and j["parent"] == "body_cam2"
    T_body3_cam3 = se3.invert_transforms(T["body_cam3"]) @ T["cam3"]
    # axis: the hinge axis in the child body's frame; origin: the hinge point
    np.testing.assert_allclose(j["axis"], T_body3_cam3[:3, :3] @ e.axis_q, atol=TOL)
    np.testing.assert_allclose(se3.transform_points(T_body3_cam3, e.o_q), 0.0, atol=TOL)
    T_cam2_body3 = se3.invert_transforms(T["cam2"]) @ T["body_cam3"]
    np.testing.assert_allclose(T_cam2_body3[:3, 3], e.o_p, atol=TOL)


def test_urdf_single_camera_and_rigid_only(rng: np.random.Generator) -> None:
    rec = rig_recording(rng, 5, joints=(("r", ("a", "b"), "rigid"),), reference="b")
    rig = rig_from_recording(rec)
    assert list(rig.cameras) == ["b", "a"]
    rig = RigArtifact("b", 0, "m", {c: rig.cameras[c] for c in "ab"}, rig.joints)
    text = urdf_from_rig(rig)
    root, joints = _urdf_kinematics(text)
    assert root == "body_a"  # the body of reference b, named after its first camera a
    _check_poses(rig, _forward(joints, root))
    assert "revolute" not in text and "not calibrated" not in text
    cam = RigCameraResult("c", np.eye(4), np.zeros(3), np.zeros(3))
    root, joints = _urdf_kinematics(urdf_from_rig(RigArtifact("c", 0, "m", {"c": cam}, {})))
    assert root == "body_c" and set(joints) == {"c"}
    np.testing.assert_array_equal(joints["c"]["origin"], np.eye(4))


def test_urdf_refuses_bad_rigs(rec: RigRecording) -> None:
    rig = rig_from_recording(rec)
    with pytest.raises(InputError, match="robot name"):
        urdf_from_rig(rig, robot_name=" ")
    # a joint named like a generated one
    bad = {k: v for k, v in rig.joints.items() if k != "r01"}
    bad["body_cam0_to_cam0"] = RigJointResult("body_cam0_to_cam0", "rigid", ("cam0", "cam1"))
    with pytest.raises(InputError, match="used twice"):
        urdf_from_rig(RigArtifact("cam0", 0, "m", rig.cameras, bad))
    no_axis = dict(rig.joints)
    no_axis["j23"] = RigJointResult("j23", "hinge", ("cam2", "cam3"), rig.joints["j23"].position_in)
    with pytest.raises(InputError, match=r"joints\.j23\.axis_in: needs both cam2 and cam3"):
        urdf_from_rig(RigArtifact("cam0", 0, "m", rig.cameras, no_axis))
    cycle = dict(rig.joints)
    cycle["x"] = RigJointResult("x", "rigid", ("cam1", "cam4"))
    with pytest.raises(InputError, match="cycle"):
        urdf_from_rig(RigArtifact("cam0", 0, "m", rig.cameras, cycle))
    units = RigArtifact("cam0", 0, "A units", rig.cameras, rig.joints)
    assert "not metres" in urdf_from_rig(units)


def test_urdf_loads_in_yourdfpy(rec: RigRecording) -> None:
    import yourdfpy  # in the test extras: a real URDF parser, as ROS tools use

    rig = rig_from_recording(rec)
    robot = yourdfpy.URDF.load(
        io.StringIO(urdf_from_rig(rig)), build_scene_graph=True, load_meshes=False
    )
    assert robot.validate()
    assert robot.base_link == "body_cam0"
    assert sorted(robot.actuated_joint_names) == ["j02_x", "j02_y", "j02_z", "j23"]
    T = {c: robot.get_transform(c, "body_cam0") for c in rig.cameras}
    _check_poses(rig, T)


# ------------------------------------------------------------------------ Kalibr


def _intrinsics(i: int, model: str = "pinhole") -> IntrinsicsArtifact:
    K = np.array([[500.0 + i, 0, 320.5], [0, 502.0 + i, 240.25], [0, 0, 1]])
    n = {"pinhole": 5, "rational": 8, "fisheye": 4}[model]
    D = np.zeros(n)
    D[:4] = [-0.1 * (i + 1), 0.01, 1e-4, -2e-4]
    return IntrinsicsArtifact(model=model, image_size=(640, 480), camera_matrix=K, distortion=D)


def test_kalibr_camchain(rec: RigRecording) -> None:
    rig = rig_from_recording(rec)
    cams = list(rig.cameras)
    intr = {c: _intrinsics(i) for i, c in enumerate(cams)}
    intr["cam3"] = _intrinsics(3, "fisheye")
    text = kalibr_camchain_from_rig(rig, intr)
    doc = yaml.safe_load(text)
    chain = check_kalibr_camchain(doc)
    assert len(chain) == 5
    # poses chain to the truth: T_cn_c0 = T_cn_cnm1 ... T_c1_c0
    T_c_0 = np.eye(4)
    T_true = rec.T_cam_ref(0)
    for i, cam in enumerate(chain):
        if i:
            T_c_0 = np.asarray(cam["T_cn_cnm1"]) @ T_c_0
        np.testing.assert_allclose(T_c_0, T_true[cams[i]], atol=TOL, rtol=0)
        assert cam["rostopic"] == f"/{cams[i]}/image_raw"
        assert cam["camera_model"] == "pinhole"
        assert cam["resolution"] == [640, 480]
        K = intr[cams[i]].camera_matrix
        assert cam["intrinsics"] == [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
        expect = "equidistant" if cams[i] == "cam3" else "radtan"
        assert cam["distortion_model"] == expect
        assert cam["distortion_coeffs"] == list(intr[cams[i]].distortion[:4])
    assert [c["cam_overlaps"] for c in chain] == [[], [], [], [], []]
    # the articulated rig is said to hold at the reference instant only
    assert "reference instant only" in text
    lines = text.splitlines()
    assert "# cam1: cam1; rigidly mounted with cam0" in lines
    assert any(
        line.startswith("# cam2: cam2; T_cn_cnm1 from cam1 across j02 (ball)") for line in lines
    )


def test_kalibr_needs_every_camera(rec: RigRecording) -> None:
    rig = rig_from_recording(rec)
    intr = {c: _intrinsics(i) for i, c in enumerate(rig.cameras)}
    del intr["cam3"]
    with pytest.raises(InputError, match=r"missing for cam3 "):
        kalibr_camchain_from_rig(rig, intr)
    with pytest.raises(InputError, match="missing for cam0, cam1, cam2, cam3, cam4"):
        kalibr_camchain_from_rig(rig, None)
    with pytest.raises(InputError, match="camX"):
        kalibr_camchain_from_rig(rig, {**intr, "cam3": _intrinsics(0), "camX": _intrinsics(0)})


def test_kalibr_refuses_what_it_cannot_hold(rec: RigRecording) -> None:
    rig = rig_from_recording(rec)
    intr = {c: _intrinsics(i) for i, c in enumerate(rig.cameras)}
    rational = _intrinsics(1, "rational")
    rational.distortion[5] = 0.3
    with pytest.raises(InputError, match="camera cam1: Kalibr's radtan"):
        kalibr_camchain_from_rig(rig, {**intr, "cam1": rational})
    rational.distortion[5] = 0.0
    doc = yaml.safe_load(kalibr_camchain_from_rig(rig, {**intr, "cam1": rational}))
    assert doc["cam1"]["distortion_model"] == "radtan"
    skew = _intrinsics(2)
    skew.camera_matrix[0, 1] = 0.5
    with pytest.raises(InputError, match=r"camera cam2: .*skew"):
        kalibr_camchain_from_rig(rig, {**intr, "cam2": skew})


def test_kalibr_reads_intrinsics_files(rec: RigRecording, tmp_path: Path) -> None:
    rig = rig_from_recording(rec)
    files = {}
    for i, c in enumerate(rig.cameras):
        intr = _intrinsics(i, "fisheye" if c == "cam4" else "pinhole")
        header = make_header("intrinsics", {}, "test", {}, {})
        body = {
            "model": intr.model,
            "image_size": list(intr.image_size),
            "camera_matrix": intr.camera_matrix,
            "distortion": intr.distortion,
        }
        files[c] = tmp_path / f"{c}.yaml"
        write_yaml_artifact(files[c], header, body)
    doc = yaml.safe_load(kalibr_camchain_from_rig(rig, {c: str(p) for c, p in files.items()}))
    check_kalibr_camchain(doc)
    assert doc["cam4"]["distortion_model"] == "equidistant"
    assert doc["cam4"]["intrinsics"] == [504.0, 506.0, 320.5, 240.25]
    files["cam2"].write_text("schema: acscal/joint\nschema_version: 1\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"cam2\.yaml"):
        kalibr_camchain_from_rig(rig, files)


def test_write_rig_export(rec: RigRecording, tmp_path: Path) -> None:
    rig = rig_from_recording(rec)
    intr = {c: _intrinsics(i) for i, c in enumerate(rig.cameras)}
    out = tmp_path / "sub" / "rig.urdf"
    text = write_rig_export(out, rig, "urdf", robot_name="r")
    assert out.read_text(encoding="utf-8") == text == urdf_from_rig(rig, "r")
    out2 = tmp_path / "camchain.yaml"
    text2 = write_rig_export(out2, rig, "kalibr", intrinsics=intr)
    assert out2.read_text(encoding="utf-8") == text2
    with pytest.raises(InputError, match="unknown rig export format 'ros'"):
        write_rig_export(tmp_path / "x", rig, "ros")
    with pytest.raises(InputError, match="missing for"):
        write_rig_export(tmp_path / "y.yaml", rig, "kalibr")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["camchain.yaml", "sub"]


def test_round_trip_through_rig_yaml(rec: RigRecording, tmp_path: Path) -> None:
    """A rig saved and loaded as ``rig.yaml`` exports the same poses."""
    rig = rig_from_recording(rec)
    path = tmp_path / "rig.yaml"
    dataclasses.replace(rig, header=make_header("rig", {}, "truth", {"length": "m"}, {})).save(path)
    loaded = RigArtifact.load(path)
    root, joints = _urdf_kinematics(urdf_from_rig(loaded))
    _check_poses(rig, _forward(joints, root))
