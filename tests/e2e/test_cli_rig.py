"""``acscal run`` over a rig config (version 2): the real CLI on real files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.io.angles import read_angles_csv
from acs_cli.io.rig import RigArtifact
from acs_cli.io.trajectory import read_trajectory, write_tum
from sample_data_gen.writer import write_rig_recording


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("rig")
    write_rig_recording(root, seed=3, frames=80)
    return root


def test_run_calibrates_the_rig_beside_its_truth(recording: Path) -> None:
    res = acscal("run", recording / "config.yaml")
    assert res.returncode == 0, res.stderr
    assert "rig: ran" in res.stdout
    rig = RigArtifact.load(recording / "out" / "rig.yaml")
    truth = yaml.safe_load((recording / "truth.yaml").read_text())
    assert rig.reference_camera == "cam0" and rig.length_unit == "m"
    for name, cam in rig.cameras.items():
        T_true = np.asarray(truth["cameras"][name]["T_cam_ref"], dtype=float)
        # 0.3 deg / 1 cm pose noise: the reference instant's poses limit T_cam_ref
        assert np.linalg.norm(cam.T_cam_ref[:3, 3] - T_true[:3, 3]) < 5 * max(
            float(np.linalg.norm(cam.translation_std)), 1e-9
        )
    s_true = float(truth["cameras"]["cam4"]["scale"])
    assert rig.cameras["cam4"].unknown_scale
    assert rig.cameras["cam4"].scale == pytest.approx(s_true, rel=0.01)
    assert rig.cameras["cam0"].scale_std is None  # fixed, not estimated
    j23 = rig.joints["j23"]
    a_true = np.asarray(truth["joints"]["j23"]["axis_in"]["cam2"], dtype=float)
    assert np.degrees(np.arccos(abs(float(j23.axis_in["cam2"] @ a_true)))) < 1.0
    assert set(rig.joints["r01"].position_in) == set()  # a rigid edge has no point
    # the whole rig over time, in cam0's frame at the reference instant
    traj = recording / "out" / "trajectories"
    assert sorted(f.name for f in traj.iterdir()) == [
        "cam0.tum", "cam1.tum", "cam2.tum", "cam3.tum", "cam4.tum", "j02.tum", "j23.tum"
    ]  # fmt: skip
    first = {c: read_trajectory(traj / f"{c}.tum", "tum").T_world_cam[0] for c in rig.cameras}
    np.testing.assert_allclose(first["cam0"], np.eye(4), atol=1e-9)
    for c, cam in rig.cameras.items():
        np.testing.assert_allclose(first[c], se3.invert_transforms(cam.T_cam_ref), atol=1e-9)
    # the run ends with a report that shows the whole rig
    assert "report: written" in res.stdout, res.stdout
    html = (recording / "out" / "report.html").read_text(encoding="utf-8")
    assert "rig of 5 cameras" in html and "j23 axis in cam2" in html
    assert (recording / "out" / "report_files" / "rig_cameras.png").stat().st_size > 10_000
    # about the rig (issue 22, item 5): each joint's residual and angles per frame, no
    # section of the pair's stages or of images
    assert {p.name for p in (recording / "out" / "report_files").iterdir()} == {
        "rig_cameras.png", "joint_residuals.png", "joint_angles.png"
    }  # fmt: skip
    assert (recording / "out" / "joint_residuals.csv").is_file()
    assert "Sections skipped" not in html and "No relpose.yaml" not in html
    # unchanged inputs: the stage is skipped
    again = acscal("run", recording / "config.yaml")
    assert again.returncode == 0 and "rig: skipped" in again.stdout


def _config(tmp: Path, recording: Path, joints: str, cams: str | None = None) -> Path:
    cams = cams or "".join(f"  cam{i}: {{poses: {recording / f'cam{i}.tum'}}}\n" for i in range(5))
    cfg = tmp / "bad.yaml"
    cfg.write_text(
        f"schema_version: 2\noutput: {tmp / 'out'}\ncameras:\n{cams}joints:\n{joints}",
        encoding="utf-8",
    )
    return cfg


CHAIN = (
    "  r01: {between: [cam0, cam1], type: rigid}\n"
    "  j02: {between: [cam0, cam2], type: ball}\n"
    "  j23: {between: [cam2, cam3], type: hinge}\n"
)


@pytest.mark.parametrize(
    ("joints", "key"),
    [
        (CHAIN + "  r34: {between: [cam3, cam4], type: rigid}\n"
         "  x14: {between: [cam1, cam4], type: ball}\n", "joints.x14.between"),
        (CHAIN + "  r34: {between: [cam3, cam9], type: rigid}\n", "joints.r34.between"),
        (CHAIN + "  r34: {between: [cam3, cam4], type: rigid}\n"
         "  again: {between: [cam2, cam3], type: ball}\n", "joints.again.between"),
        (CHAIN, "cameras.cam4"),
        (CHAIN + "  r34: {between: [cam3, cam4], type: slider}\n", "joints.r34.type"),
    ],
    ids=["cycle", "unknown camera", "two joints one pair", "camera in no joint", "bad type"],
)  # fmt: skip
def test_bad_rig_exits_2_naming_the_key(
    tmp_path: Path, recording: Path, joints: str, key: str
) -> None:
    res = acscal("run", _config(tmp_path, recording, joints))
    assert res.returncode == 2, res.stdout + res.stderr
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and key in lines[0], res.stderr
    assert not (tmp_path / "out").exists()  # nothing written


def test_neighbours_that_never_overlap_in_time_exit_2(tmp_path: Path, recording: Path) -> None:
    late = read_trajectory(recording / "cam4.tum", "tum")
    write_tum(tmp_path / "cam4_late.tum", late.timestamps + 1000.0, late.T_world_cam)
    cams = "".join(f"  cam{i}: {{poses: {recording / f'cam{i}.tum'}}}\n" for i in range(4))
    cams += f"  cam4: {{poses: {tmp_path / 'cam4_late.tum'}, scale: unknown}}\n"
    cfg = _config(
        tmp_path, recording, CHAIN + "  r34: {between: [cam3, cam4], type: rigid}\n", cams
    )
    res = acscal("run", cfg)
    assert res.returncode == 2, res.stdout + res.stderr
    assert "joints.r34" in res.stderr and "no instant in common" in res.stderr
    assert not (tmp_path / "out" / "rig.yaml").exists()


def test_a_planar_hinge_exits_3_naming_the_joint(tmp_path: Path) -> None:
    from sample_data_gen.rig_sim import EdgeTruth, make_edges, rig_recording

    rng = np.random.default_rng(1)
    joints = (("hitch", ("truck", "trailer"), "hinge"),)
    edges = make_edges(rng, joints)
    z = np.array([0.0, 0.0, 1.0])
    e = edges["hitch"]
    edges["hitch"] = EdgeTruth(
        "hitch", e.between, "hinge", se3.matrix_from_rotvec(0.3 * z), e.o_p - (e.o_p @ z) * z,
        e.o_q, z,
    )  # fmt: skip
    rec = rig_recording(
        rng, 60, joints=joints, reference="truck", edges=edges, planar=True,
        sigma_rot_deg=0.2, sigma_trans=0.005,
    )  # fmt: skip
    for c, T in rec.T_wc_c.items():
        write_tum(tmp_path / f"{c}.tum", rec.timestamps, T)
    cfg = tmp_path / "truck.yaml"
    cfg.write_text(
        "schema_version: 2\noutput: out\ncameras:\n  truck: {poses: truck.tum}\n"
        "  trailer: {poses: trailer.tum}\njoints:\n"
        "  hitch: {between: [truck, trailer], type: hinge}\n",
        encoding="utf-8",
    )
    res = acscal("run", cfg)
    assert res.returncode == 3, res.stdout + res.stderr
    assert "joint hitch (truck-trailer)" in res.stderr
    assert "along the hinge axis" in res.stderr and "position_in.trailer" in res.stderr
    assert not (tmp_path / "out" / "rig.yaml").exists()
    # the offset from the config (a tape measure): the run goes through
    o_q = rec.edges["hitch"].o_q
    cfg.write_text(
        cfg.read_text(encoding="utf-8").replace(
            "type: hinge}",
            f"type: hinge, position_in: {{trailer: [{o_q[0]}, {o_q[1]}, {o_q[2]}]}}, "
            "position_std: 0.005}",
        ),
        encoding="utf-8",
    )
    res = acscal("run", cfg)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "out" / "rig.yaml").is_file()


def test_export_a_rig_as_urdf_and_refuse_kalibr_without_intrinsics(
    recording: Path, tmp_path: Path
) -> None:
    import xml.etree.ElementTree as ET

    rig_file = recording / "out" / "rig.yaml"
    if not rig_file.is_file():
        assert acscal("run", recording / "config.yaml").returncode == 0
    res = acscal(
        "export", rig_file, "--format", "urdf", "--limit-margin", "5", "-o", tmp_path / "rig.urdf"
    )
    assert res.returncode == 0, res.stderr
    assert "wrote" in res.stdout
    robot = ET.parse(tmp_path / "rig.urdf").getroot()
    joints = {j.get("name"): j.get("type") for j in robot.iter("joint")}
    assert joints["j23"] == "revolute" and joints["r34"] == "fixed"
    assert {"j02_x", "j02_y", "j02_z"} <= set(joints)  # a ball: three revolutes
    # the hinge's limits: its angle range over the calibration, 5 deg wider either side (in
    # the URDF joint's sense, the range itself or its negation)
    lo, hi = yaml.safe_load(rig_file.read_text())["joints"]["j23"]["angle_range_deg"]
    assert hi - lo > 10.0
    limit = next(j for j in robot.iter("joint") if j.get("name") == "j23").find("limit")
    assert limit is not None
    got = sorted(np.degrees([float(limit.get("lower", "nan")), float(limit.get("upper", "nan"))]))
    assert got == pytest.approx([lo - 5, hi + 5], abs=1e-4) or got == pytest.approx(
        [-hi - 5, -lo + 5], abs=1e-4
    )
    bad = acscal(
        "export", rig_file, "--format", "urdf", "--limit-margin", "-1", "-o", tmp_path / "x"
    )
    assert bad.returncode == 2 and not (tmp_path / "x").exists()
    res = acscal("export", rig_file, "--format", "kalibr", "-o", tmp_path / "cc.yaml")
    assert res.returncode == 2 and "intrinsics" in res.stderr
    assert not (tmp_path / "cc.yaml").exists()
    res = acscal("export", rig_file, "--format", "opencv", "-o", tmp_path / "cv.yaml")
    assert res.returncode == 2 and "kalibr, ros, urdf" in res.stderr


def test_trajectory_of_a_rig_from_rig_yaml(recording: Path, tmp_path: Path) -> None:
    rig_file = recording / "out" / "rig.yaml"
    if not rig_file.is_file():
        assert acscal("run", recording / "config.yaml").returncode == 0
    res = acscal("trajectory", "--rig", rig_file, "-o", tmp_path / "traj")
    assert res.returncode == 0, res.stderr
    for name in ("cam0", "cam4", "j23"):
        mine = read_trajectory(tmp_path / "traj" / f"{name}.tum", "tum").T_world_cam
        run = read_trajectory(recording / "out" / "trajectories" / f"{name}.tum", "tum").T_world_cam
        # every frame but the reference instant (corrected there by the joint constraints)
        np.testing.assert_allclose(mine[1:], run[1:], atol=1e-6)
        assert np.linalg.norm(mine[0, :3, 3] - run[0, :3, 3]) < 0.1
    # every ball and hinge joint's angles (issue 22): a hinge's with its std, a ball's Euler
    angles = read_angles_csv(tmp_path / "traj" / "angles.csv")
    art = RigArtifact.load(rig_file)
    assert set(angles) == {n for n, j in art.joints.items() if j.type in ("ball", "hinge")}
    hinge = angles["j23"]
    assert np.all(np.isfinite(hinge["angle_deg"])) and np.nanmax(np.abs(hinge["angle_deg"])) > 5
    assert np.sum(hinge["angle_deg"] == 0.0) >= 1 and np.all(hinge["angle_std_deg"] >= 0.0)
    assert np.all(np.isnan(angles["j02"]["angle_deg"]))
    # rig.yaml reports the hinge's wobble: the noise here, and the angles.csv's wobble's RMS
    wobble = art.joints["j23"].wobble_rms_deg
    assert wobble is not None and 0.0 < wobble < 3.0
    assert art.joints["j02"].wobble_rms_deg is None
    assert np.all(np.isfinite(angles["j02"]["euler_1_deg"]))
    # a ball joint's std (issue 22, item 1): from its bodies' rotation noise as the solve
    # fitted it (cam0's from the rigid r01, cam2's from the hinge j23; the recording's is
    # 0.3 deg per axis and pose), 2 sigma on each rotation-vector component, 0 at the zero
    s0, s2 = (art.cameras[c].sigma_rotation_deg for c in ("cam0", "cam2"))
    assert s0 is not None and s2 is not None and 0.2 < s0 < 0.45 and 0.2 < s2 < 0.45
    std = angles["j02"]["rotvec_std_deg"]
    assert np.sum(std == 0.0) == 1
    np.testing.assert_allclose(std[std > 0], 2 * np.hypot(s0, s2) / np.sqrt(2), rtol=1e-5)
    assert np.all(np.isfinite(angles["j02"]["euler_1_std_deg"]))
    bad = acscal("trajectory", "--rig", rig_file, "--poses-a", "x.tum", "-o", tmp_path / "t2")
    assert bad.returncode == 2 and "--rig replaces" in bad.stderr
    # --zero-at: every joint's angles zero at the frame nearest that time
    t10 = float(hinge["time"][10])
    res = acscal("trajectory", "--rig", rig_file, "--zero-at", str(t10), "-o", tmp_path / "z")
    assert res.returncode == 0, res.stderr
    moved = read_angles_csv(tmp_path / "z" / "angles.csv")
    assert moved["j23"]["angle_deg"][10] == 0.0
    # a twist from another zero is the difference of the twists up to the off-axis wobble's
    # second order (0.3 deg of noise here: about 0.01 deg)
    np.testing.assert_allclose(
        moved["j23"]["angle_deg"], hinge["angle_deg"] - hinge["angle_deg"][10], atol=0.05
    )
    assert np.all(np.stack([moved["j02"][f"rotvec_{c}_deg"] for c in "xyz"])[:, 10] == 0.0)
    # --poses: the calibration's own recording maps as before; another session of the rig
    # (here cam2's world moved by 1 m and 30 deg) does not fit its worlds and is refused
    from acs_cli.core import se3
    from acs_cli.io.trajectory import write_tum

    cam2 = read_trajectory(recording / "cam2.tum", "tum")
    write_tum(tmp_path / "same.tum", cam2.timestamps, cam2.T_world_cam)
    res = acscal("trajectory", "--rig", rig_file, "--poses", f"cam2={tmp_path / 'same.tum'}",
                 "-o", tmp_path / "t3")  # fmt: skip
    assert res.returncode == 0, res.stderr
    moved = se3.transforms_from_rt(se3.matrix_from_rotvec(np.radians([0.0, 30.0, 0.0])), [1, 0, 0])
    write_tum(tmp_path / "other.tum", cam2.timestamps, moved @ cam2.T_world_cam)
    res = acscal("trajectory", "--rig", rig_file, "--poses", f"cam2={tmp_path / 'other.tum'}",
                 "-o", tmp_path / "t4")  # fmt: skip
    assert res.returncode == 2 and "not in the worlds it calibrated" in res.stderr
    assert "joint j02" in res.stderr and not (tmp_path / "t4").exists()


def test_a_rig_of_image_folders_calibrates_intrinsics_poses_and_rig(tmp_path: Path) -> None:
    """Cameras given as board images: intrinsics and poses stages run before the rig."""
    from sample_data_gen.render import render_scenario

    render_scenario(tmp_path / "images", "general", seed=2, frames=20, size=(640, 480))
    cfg = tmp_path / "rig.yaml"
    cfg.write_text(
        "schema_version: 2\noutput: run\nboard: {cols: 9, rows: 6, square: 0.025}\n"
        "cameras:\n  a: {images: images/general/cam_a}\n  b: {images: images/general/cam_b}\n"
        "joints:\n  j: {between: [a, b], type: ball}\n",
        encoding="utf-8",
    )
    res = acscal("run", cfg)
    assert res.returncode == 0, res.stdout + res.stderr
    for stage in ("intrinsics a", "poses a", "intrinsics b", "poses b", "rig"):
        assert f"{stage}: ran" in res.stdout, res.stdout
    rig = RigArtifact.load(tmp_path / "run" / "rig.yaml")
    assert "poses_a" in rig.inputs and str(rig.inputs["poses_a"]["path"]).endswith("poses.npz")
    truth = yaml.safe_load((tmp_path / "images" / "general" / "truth.yaml").read_text())
    o_a = np.asarray(truth["joint"]["position_in_a"], dtype=float)
    err = float(np.linalg.norm(rig.joints["j"].position_in["a"] - o_a))
    # refined by the rig's bundle adjustment on both cameras' corners (0.15 mm; 0.64 mm from
    # the PnP poses alone, measured with bundle: false)
    assert err < 0.002, (err, rig.joints["j"].position_in["a"], o_a)
    assert set(rig.bundle_adjustment) == {"a", "b"}
    assert all(b.rms_px < 0.1 and b.frames >= 10 for b in rig.bundle_adjustment.values())
    assert "bundle adjustment" in rig.header["method"]
    assert "bundle adjustment RMS" in res.stdout


def test_a_rig_with_joint_priors_gets_its_bundle_adjustment(tmp_path: Path) -> None:
    """Issue 19: board cameras (poses NPZs with their corners) and joints known beforehand,
    a ball's centre from a fixed-joint session of cam0 and a hinge's line and axis from one
    of cam2: the bundle adjustment fuses them with the corners (it used to be skipped)."""
    from sample_data_gen.rig_sim import fixed_joint_motion, rig_corner_recording
    from sample_data_gen.writer import write_corner_poses

    joints = (("j01", ("cam0", "cam1"), "ball"), ("h12", ("cam1", "cam2"), "hinge"))
    rng = np.random.default_rng(11)
    rec = rig_corner_recording(rng, 80, joints=joints)
    write_corner_poses(tmp_path, rec)
    ball, hinge = rec.rig.edges["j01"], rec.rig.edges["h12"]
    assert hinge.axis_q is not None and hinge.axis_p is not None
    for name, T in (
        ("fj01_cam0", fixed_joint_motion(rng, ball.o_p)),
        ("fh12_cam2", fixed_joint_motion(rng, hinge.o_q, hinge.axis_q)),
    ):
        write_tum(tmp_path / f"{name}.tum", np.arange(T.shape[0]) * 0.1, T)
    cfg = tmp_path / "rig.yaml"
    cfg.write_text(
        "schema_version: 2\noutput: out\ncameras:\n"
        "  cam0: {poses: cam0.npz}\n  cam1: {poses: cam1.npz}\n  cam2: {poses: cam2.npz}\n"
        "joints:\n"
        "  j01: {between: [cam0, cam1], type: ball, fixed_joint: {cam0: fj01_cam0.tum}}\n"
        "  h12: {between: [cam1, cam2], type: hinge, fixed_joint: {cam2: fh12_cam2.tum}}\n",
        encoding="utf-8",
    )
    res = acscal("run", cfg, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "no bundle adjustment" not in res.stderr, res.stderr
    rig = RigArtifact.load(tmp_path / "out" / "rig.yaml")
    assert set(rig.bundle_adjustment) == {"cam0", "cam1", "cam2"}
    assert "bundle adjustment" in rig.header["method"]
    assert {"fixed_joint_j01_cam0", "fixed_joint_h12_cam2"} <= set(rig.header["inputs"])
    for name, truth in (("j01", ball), ("h12", hinge)):
        j = rig.joints[name]
        p, q = j.between
        for c, o in ((p, truth.o_p), (q, truth.o_q)):
            err = float(np.linalg.norm(j.position_in[c] - o))
            assert err < 4 * np.linalg.norm(j.position_std_in[c]) and err < 0.005, (name, c, err)
    u = rig.joints["h12"].axis_in["cam2"]
    ang = np.degrees(np.arccos(min(1.0, abs(float(u @ hinge.axis_q)))))
    assert ang < 4 * rig.joints["h12"].axis_std_deg_in["cam2"] and ang < 0.2, ang
    # the run's trajectories hold the bundle's per-frame fit: closer to the truth than the
    # measured poses mapped by the calibration (acscal trajectory --rig, which says so)
    res = acscal("trajectory", "--rig", tmp_path / "out" / "rig.yaml", "-o", tmp_path / "t")
    assert res.returncode == 0 and "refined by a bundle adjustment" in res.stderr, res.stderr
    T_W = rec.rig.T_W_c
    for c in ("cam1", "cam2", "h12"):
        path = tmp_path / "out" / "trajectories" / f"{c}.tum"
        run, mapped = (
            read_trajectory(path, "tum"),
            read_trajectory(tmp_path / "t" / f"{c}.tum", "tum"),
        )
        # the rows the bundle adjusted, as the file's note lists them (each camera sees its
        # board there); every one of them is in the mapped file too
        note = path.read_text(encoding="utf-8").splitlines()[1]
        fitted = np.array(note.split("those at t = ")[1].split(";")[0].split(), float)
        assert 20 < fitted.size < run.timestamps.size, note
        mine = run.T_world_cam[np.isin(run.timestamps, fitted)]
        theirs = mapped.T_world_cam[np.isin(mapped.timestamps, fitted)]
        assert mine.shape == theirs.shape == (fitted.size, 4, 4)
        body = "cam1" if c == "h12" else c
        truth = se3.invert_transforms(T_W["cam0"][0]) @ T_W[body][np.round(fitted * 30).astype(int)]
        o = se3.transform_points(truth, hinge.o_p if c == "h12" else np.zeros(3))
        err = [np.sqrt(np.mean(np.sum((T[:, :3, 3] - o) ** 2, 1))) for T in (mine, theirs)]
        # 2-3 mm RMS against 19-22 mm (seed 11)
        assert err[0] < 0.3 * err[1], (c, err)


def test_a_chain_from_two_recordings_gets_one_bundle_adjustment(tmp_path: Path) -> None:
    """Issue 19: cam0 -ball- cam1 -hinge- cam2 from a hip trial (cam0, cam1) and a knee
    trial (cam1, cam2), every camera's poses with their corners: one bundle adjustment over
    both recordings puts both joints within their stds (it used to solve them from poses)."""
    from sample_data_gen.rig_sim import rig_corner_recording
    from sample_data_gen.writer import write_corner_poses

    joints = (("hip", ("cam0", "cam1"), "ball"), ("knee", ("cam1", "cam2"), "hinge"))
    n = 160
    rec = rig_corner_recording(np.random.default_rng(5), n, joints=joints)
    halves = {"hip": range(n // 2, n), "knee": range(n // 2)}
    for name, out in halves.items():
        (tmp_path / name).mkdir()
        write_corner_poses(
            tmp_path / name, rec, drop={c: list(out) for c in rec.rig.topology.cameras}
        )
    cfg = tmp_path / "rig.yaml"
    cfg.write_text(
        "schema_version: 2\noutput: out\n"
        "reference: {camera: cam0, recording: hip, frame: 0}\n"
        "recordings:\n"
        "  hip:\n    cameras: {cam0: {poses: hip/cam0.npz}, cam1: {poses: hip/cam1.npz}}\n"
        "  knee:\n    cameras: {cam1: {poses: knee/cam1.npz}, cam2: {poses: knee/cam2.npz}}\n"
        "joints:\n"
        "  hip: {between: [cam0, cam1], type: ball}\n"
        "  knee: {between: [cam1, cam2], type: hinge}\n",
        encoding="utf-8",
    )
    res = acscal("run", cfg, cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "no bundle adjustment" not in res.stderr, res.stderr
    rig = RigArtifact.load(tmp_path / "out" / "rig.yaml")
    assert set(rig.bundle_adjustment) == {"cam0", "cam1", "cam2"}
    for name, _, _ in joints:
        truth = rec.rig.edges[name]
        j = rig.joints[name]
        p, q = j.between
        for c, o in ((p, truth.o_p), (q, truth.o_q)):
            err = float(np.linalg.norm(j.position_in[c] - o))
            assert err < 4 * np.linalg.norm(j.position_std_in[c]) and err < 0.005, (name, c, err)
