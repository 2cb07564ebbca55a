"""``acscal export`` (and ``acscal intrinsics --export``) end to end, read by the consumers.

Two cameras from simulated trajectories (a fixed-joint session, then general motion, with
known and with unknown scale), a rig from ``acscal run`` on a simulated rig recording, and
OpenCV's sample photographs for the per-camera exports; every file is loaded with its
consumer's reader (``tests/export_consumers.py``, ``cv2.FileStorage``, evo). Each behaviour
runs once through the ``acscal`` command (options, exit codes, messages); its variants call
the stage in-process.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal
from export_consumers import read_kalibr_camchain, read_ros_camera_info

from acs_cli.cli.options import parse_list_option
from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.trajectory import write_tum
from acs_cli.stages.export import run_export
from acs_cli.stages.joint import JointConfig, run_joint
from acs_cli.stages.relpose import RelposeConfig, run_relpose
from sample_data_gen import acs_sim
from sample_data_gen.writer import write_rig_recording

PHOTOS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "opencv_chessboard"
#: Camera B's trajectory units per metre in the unknown-scale recording (A's: 0.8).
MU_B = 3.2


def _intrinsics_file(path: Path, model: str, fx: float) -> None:
    """An ``acscal/intrinsics`` file, as ``acscal intrinsics`` writes one."""
    n = {"pinhole": 5, "fisheye": 4}[model]
    D = [-0.2, 0.03, 2e-4, -1e-4, 0.0][:n]
    K = [[fx, 0.0, 376.5], [0.0, fx + 1.0, 240.25], [0.0, 0.0, 1.0]]
    body = {"model": model, "image_size": [752, 480], "camera_matrix": K, "distortion": D}
    write_yaml_artifact(path, make_header("intrinsics", {}, "test", {}, {}), body)


def _T(doc_path: Path) -> np.ndarray:
    return np.array(yaml.safe_load(doc_path.read_text())["relative_pose"]["T_b_a"], dtype=float)


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """A run folder: joint.yaml, relpose.yaml and cam_<x>/intrinsics.yaml; and variants.

    The artifacts are made by the stages in-process (``acscal joint`` and ``acscal relpose``
    end to end are tested elsewhere); only the exports run through the CLI.
    """
    rng = np.random.default_rng(11)
    rig = acs_sim.make_rig(rng)
    d = tmp_path_factory.mktemp("pair")
    run = d / "run"
    seqs = {
        "fixed": acs_sim.fixed_joint_sequence(rng, rig, 25),
        "overlap": acs_sim.general_sequence(rng, rig, 25, shared_world=True),
        "general": acs_sim.general_sequence(rng, rig, 25),
    }
    f: dict = {"d": d, "run": run, "truth": seqs["general"].T_b_a(0)}
    for name, seq in seqs.items():
        for cam, T, mu in (("a", seq.T_wa_a, 0.8), ("b", seq.T_wb_b, MU_B)):
            noisy = acs_sim.add_pose_noise(rng, T, 0.1, 0.002)
            write_tum(d / f"{name}_{cam}.tum", seq.timestamps, noisy)
            in_units = acs_sim.scale_translations(noisy, mu)
            write_tum(d / f"{name}_{cam}_scaled.tum", seq.timestamps, in_units)

    def paths(name: str, suffix: str = "") -> tuple[Path, Path]:
        return d / f"{name}_a{suffix}.tum", d / f"{name}_b{suffix}.tum"

    joint, general = run / "joint.yaml", paths("general")
    run_joint(*paths("fixed"), joint, JointConfig())
    run_relpose(*general, joint, run / "relpose.yaml", RelposeConfig())
    run_joint(*paths("overlap"), d / "overlap_joint.yaml", JointConfig(scenario="overlap"))
    run_relpose(*general, d / "overlap_joint.yaml", d / "ov.yaml", RelposeConfig())
    scaled = paths("general", "_scaled")
    # the metric joint taken as if in the trajectories' own units: a fit past the refusal
    # level (issue 13), written with --accept-weak: a result that carries warnings
    weak = RelposeConfig(unknown_scale=True, accept_weak=True)
    run_relpose(*scaled, joint, d / "unknown.yaml", weak)
    metric = RelposeConfig(unknown_scale=True, joint_metric=True)
    run_relpose(*scaled, joint, d / "metric.yaml", metric)
    # --length-unit: the trajectories' unit. In mm: the metric joint is converted to it
    for x, T in zip("ab", (seqs["general"].T_wa_a, seqs["general"].T_wb_b), strict=True):
        write_tum(d / f"general_{x}_mm.tum", seqs["general"].timestamps,
                  acs_sim.scale_translations(T, 1000.0))  # fmt: skip
    run_relpose(*paths("general", "_mm"), joint, d / "mm.yaml", RelposeConfig(length_unit="mm"))
    # a unit acscal cannot convert: a joint from the same recording (self-calibrated)
    furlong = RelposeConfig(length_unit="furlong", self_calibrate=True)
    run_relpose(*general, None, d / "furlong.yaml", furlong)
    _intrinsics_file(run / "cam_a" / "intrinsics.yaml", "pinhole", 600.0)
    _intrinsics_file(run / "cam_b" / "intrinsics.yaml", "fisheye", 420.0)
    for x in ("a", "b"):  # the variants take the run's intrinsics by path
        f[f"intr_{x}"] = run / f"cam_{x}" / "intrinsics.yaml"
    return f


def test_kalibr_camchain_of_a_relpose_from_the_run_folder(pair: dict, tmp_path: Path) -> None:
    out = tmp_path / "camchain.yaml"
    res = acscal("export", pair["run"] / "relpose.yaml", "--format", "kalibr", "-o", out)
    assert res.returncode == 0, res.stderr
    assert f"wrote {out}" in res.stdout and "intrinsics of cam_b:" in res.stdout
    cam0, cam1 = read_kalibr_camchain(out)
    T_b_a = _T(pair["run"] / "relpose.yaml")
    np.testing.assert_allclose(cam1["T_cn_cnm1"], T_b_a, atol=1e-12)  # metres already
    truth = pair["truth"]
    assert np.linalg.norm(cam1["T_cn_cnm1"][:3, 3] - truth[:3, 3]) < 0.05
    assert cam0["intrinsics"] == [600.0, 601.0, 376.5, 240.25]
    assert (cam0["distortion_model"], cam1["distortion_model"]) == ("radtan", "equidistant")
    assert cam1["distortion_coeffs"] == [-0.2, 0.03, 2e-4, -1e-4]
    assert (cam0["resolution"], cam1["rostopic"]) == ([752, 480], "/cam_b/image_raw")
    assert cam0["cam_overlaps"] == cam1["cam_overlaps"] == []  # a fixed-joint session
    text = out.read_text()
    assert "holds at the reference instant only" in text
    assert "run/cam_a/intrinsics.yaml" in text


def test_overlapping_cameras_and_the_camera_name(pair: dict, tmp_path: Path) -> None:
    out = tmp_path / "camchain.yaml"
    res = acscal(
        "export", pair["d"] / "ov.yaml", "-o", out, "--intrinsics", f"a={pair['intr_a']}",
        "--intrinsics", f"cam_b={pair['intr_b']}", "--camera-name", "a=left",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    cam0, cam1 = read_kalibr_camchain(out)
    assert (cam0["cam_overlaps"], cam1["cam_overlaps"]) == ([1], [0])  # joint --overlap
    assert (cam0["rostopic"], cam1["rostopic"]) == ("/left/image_raw", "/cam_b/image_raw")
    with pytest.raises(InputError, match="missing for cam_a, cam_b"):
        run_export(pair["d"] / "ov.yaml", tmp_path / "x.yaml", "kalibr")
    assert not (tmp_path / "x.yaml").exists()


def test_opencv_and_ros_of_a_relpose(pair: dict, tmp_path: Path) -> None:
    rel = pair["run"] / "relpose.yaml"
    out = tmp_path / "stereo.yaml"
    run_export(rel, out, "opencv")
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    try:
        T_b_a = _T(rel)
        np.testing.assert_allclose(fs.getNode("R").mat(), T_b_a[:3, :3], atol=1e-12)
        np.testing.assert_allclose(fs.getNode("T").mat().ravel(), T_b_a[:3, 3], atol=1e-12)
        cam_b = fs.getNode("cam_b")
        assert cam_b.getNode("camera_name").string() == "cam_b"
        assert cam_b.getNode("model").string() == "fisheye"
        assert cam_b.getNode("camera_matrix").mat()[0, 0] == 420.0
        assert cam_b.getNode("distortion_coefficients").mat().shape == (1, 4)
        assert int(cam_b.getNode("image_width").real()) == 752
        assert fs.getNode("length_unit").string() == "m"
    finally:
        fs.release()
    ros = tmp_path / "ros"
    res = acscal("export", rel, "--format", "ros", "--camera-name", "b=right", "-o", ros)
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in ros.iterdir()) == ["cam_a.yaml", "right.yaml"]
    left, right = read_ros_camera_info(ros / "cam_a.yaml"), read_ros_camera_info(ros / "right.yaml")
    assert (left["camera_name"], left["distortion_model"]) == ("cam_a", "plumb_bob")
    assert (right["camera_name"], right["distortion_model"]) == ("right", "equidistant")
    assert right["K"][0] == 420.0 and right["D"].size == 4
    with pytest.raises(InputError, match="cameras are a and b"):
        run_export(rel, tmp_path / "r2", "ros", camera_names={"c": "x"})


def test_unknown_scale_is_never_exported_silently(pair: dict, tmp_path: Path) -> None:
    unknown, metric = pair["d"] / "unknown.yaml", pair["d"] / "metric.yaml"
    intr = ["--intrinsics", f"a={pair['intr_a']}", "--intrinsics", f"b={pair['intr_b']}"]
    out = tmp_path / "kalibr.yaml"
    res = acscal("export", unknown, "--format", "kalibr", *intr, "-o", out)
    assert res.returncode == 2, res.stderr
    assert "unknown scale" in res.stderr and "--joint-metric" in res.stderr
    assert "--scale" in res.stderr and not out.exists()
    with pytest.raises(InputError, match="unknown scale"):
        run_export(unknown, tmp_path / "cv.yaml", "opencv")
    run_export(unknown, tmp_path / "cv.json", "opencv", scale=0.5)  # JSON: no comments
    fs = cv2.FileStorage(str(tmp_path / "cv.json"), cv2.FILE_STORAGE_READ)
    marked = fs.getNode("warnings").string()
    fs.release()
    assert marked == "; ".join(yaml.safe_load(unknown.read_text())["warnings"])
    # an explicit scale: metres per unit of B's trajectory
    out = tmp_path / "scaled.yaml"
    res = acscal("export", unknown, *intr, "--scale", str(1 / MU_B), "-o", out)
    assert res.returncode == 0, res.stderr
    (_, cam1) = read_kalibr_camchain(out)
    np.testing.assert_allclose(cam1["T_cn_cnm1"][:3, 3], _T(unknown)[:3, 3] / MU_B, atol=1e-12)
    text = out.read_text()
    assert "--scale 0.3125 m per unit of B" in text
    # ... and the artifact's warnings are marked in the export
    warnings = yaml.safe_load(unknown.read_text())["warnings"]
    assert warnings and all(f"# WARNING: {w}" in text for w in warnings)
    assert "# WEAK RESULT: unknown.yaml was refused and written only with --accept-weak" in text
    # through the metric joint: mu_b
    out = tmp_path / "metric.yaml"
    run_export(metric, out, "kalibr", intrinsics={"a": pair["intr_a"], "b": pair["intr_b"]})
    (_, cam1) = read_kalibr_camchain(out)
    mu_b = yaml.safe_load(metric.read_text())["scale"]["mu_b"]
    np.testing.assert_allclose(cam1["T_cn_cnm1"][:3, 3], _T(metric)[:3, 3] / mu_b, atol=1e-12)
    assert np.linalg.norm(cam1["T_cn_cnm1"][:3, 3] - pair["truth"][:3, 3]) < 0.05
    assert "the metric joint's mu_a, mu_b" in out.read_text()


def test_the_length_unit_is_honoured(pair: dict, tmp_path: Path) -> None:
    mm, furlong = pair["d"] / "mm.yaml", pair["d"] / "furlong.yaml"
    out = tmp_path / "mm_cv.yaml"
    run_export(mm, out, "opencv")
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    T = fs.getNode("T").mat().ravel()
    assert fs.getNode("length_unit").string() == "m"
    fs.release()
    np.testing.assert_allclose(T, 1e-3 * _T(mm)[:3, 3], atol=1e-15)
    res = acscal("export", furlong, "--format", "opencv", "-o", tmp_path / "f.yaml")
    assert res.returncode == 2 and "'furlong'" in res.stderr and "--scale" in res.stderr
    run_export(furlong, out, "opencv", scale=201.168)
    fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("T").mat().ravel(), 201.168 * _T(furlong)[:3, 3])
    fs.release()
    with pytest.raises(InputError, match="--scale must be a positive"):
        run_export(mm, out, "opencv", scale=-1.0)


# ------------------------------------------------------------------------ a rig


@pytest.fixture(scope="module")
def rig_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``acscal run`` on a small simulated rig (poses only), with intrinsics beside it."""
    root = tmp_path_factory.mktemp("rig")
    write_rig_recording(root, seed=3, frames=40)
    res = acscal("run", root / "config.yaml")
    assert res.returncode == 0, res.stderr
    out = root / "out"
    cams = list(yaml.safe_load((out / "rig.yaml").read_text())["cameras"])
    for i, cam in enumerate(cams):
        _intrinsics_file(out / f"cam_{cam}" / "intrinsics.yaml", "pinhole", 500.0 + i)
    return out


def test_rig_exports_read_by_kalibr_ros_and_evo(rig_run: Path, tmp_path: Path) -> None:
    from evo.tools import file_interface

    rig_file = rig_run / "rig.yaml"
    doc = yaml.safe_load(rig_file.read_text())
    cams = list(doc["cameras"])
    out = tmp_path / "camchain.yaml"
    res = acscal("export", rig_file, "--format", "kalibr", "-o", out)
    assert res.returncode == 0, res.stderr
    chain = read_kalibr_camchain(out)
    assert len(chain) == len(cams) == 5
    T_ref = {c: np.array(doc["cameras"][c]["T_cam_ref"], dtype=float) for c in cams}
    T_c_0 = np.eye(4)
    for i, cam in enumerate(chain):
        if i:
            T_c_0 = cam["T_cn_cnm1"] @ T_c_0
        expect = T_ref[cams[i]] @ se3.invert_transforms(T_ref[cams[0]])
        np.testing.assert_allclose(T_c_0, expect, atol=1e-9)
        assert cam["intrinsics"][0] == 500.0 + i and cam["cam_overlaps"] == []
    assert "holds at the reference instant only" in out.read_text()
    ros = tmp_path / "ros"
    res = acscal("export", rig_file, "--format", "ros", "--camera-name", "cam0=front", "-o", ros)
    assert res.returncode == 0, res.stderr
    names = sorted(p.stem for p in ros.iterdir())
    assert names == sorted(["front", *cams[1:]])
    assert all(read_ros_camera_info(ros / f"{n}.yaml")["camera_name"] == n for n in names)
    # the rig's trajectories (TUM) read in evo
    for tum in sorted((rig_run / "trajectories").glob("*.tum")):
        traj = file_interface.read_tum_trajectory_file(str(tum))
        assert traj.num_poses > 10
        assert np.all(np.isfinite(traj.positions_xyz))


def test_a_rig_in_unknown_units_needs_a_scale(rig_run: Path, tmp_path: Path) -> None:
    doc = yaml.safe_load((rig_run / "rig.yaml").read_text())
    doc["length_unit"] = "cam4 units"
    rig_file = tmp_path / "rig.yaml"
    rig_file.write_text(yaml.safe_dump(doc))
    for cam in doc["cameras"]:
        (tmp_path / f"cam_{cam}").mkdir()
        shutil.copy(rig_run / f"cam_{cam}" / "intrinsics.yaml", tmp_path / f"cam_{cam}")
    out = tmp_path / "camchain.yaml"
    res = acscal("export", rig_file, "-o", out)
    assert res.returncode == 2 and "cam4 units" in res.stderr and "--scale" in res.stderr
    assert not out.exists()
    run_export(rig_file, out, "kalibr", scale=0.5)
    chain = read_kalibr_camchain(out)
    T_ref = {c: np.array(doc["cameras"][c]["T_cam_ref"], dtype=float) for c in doc["cameras"]}
    cams = list(doc["cameras"])
    expect = T_ref[cams[1]] @ se3.invert_transforms(T_ref[cams[0]])
    np.testing.assert_allclose(chain[1]["T_cn_cnm1"][:3, 3], 0.5 * expect[:3, 3], atol=1e-12)
    with pytest.raises(InputError, match="a rig exports as kalibr, ros, urdf, handeye, not 'open"):
        run_export(rig_file, tmp_path / "cv.yaml", "opencv")


def test_trajectory_tum_files_read_in_evo(pair: dict, tmp_path: Path) -> None:
    from evo.tools import file_interface

    run = pair["run"]
    res = acscal(
        "trajectory", "--joint", run / "joint.yaml", "--relpose", run / "relpose.yaml",
        "--poses-a", pair["d"] / "general_a.tum", "--poses-b", pair["d"] / "general_b.tum",
        "-o", tmp_path / "traj",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    for name in ("cam_a", "cam_b", "joint"):
        traj = file_interface.read_tum_trajectory_file(str(tmp_path / "traj" / f"{name}.tum"))
        assert traj.num_poses == 25
    cam_a = file_interface.read_tum_trajectory_file(str(tmp_path / "traj" / "cam_a.tum"))
    np.testing.assert_allclose(cam_a.poses_se3[0], np.eye(4), atol=1e-6)  # A at the reference


# ------------------------------------------------------------------------ one camera


@pytest.mark.skipif(not PHOTOS.is_dir(), reason=f"OpenCV sample photographs not at {PHOTOS}")
def test_intrinsics_exports_as_a_list_and_poses_tum_in_evo(tmp_path: Path) -> None:
    from evo.tools import file_interface

    imgs = tmp_path / "left"
    imgs.mkdir()
    for p in sorted(PHOTOS.glob("left*.jpg")):
        shutil.copy(p, imgs / p.name)
    intr = tmp_path / "out" / "intrinsics.yaml"
    board = ["--board", "9x6", "--square", "0.025"]
    res = acscal("intrinsics", imgs, *board, "-o", intr, "--export", "ros,opencv",
                 "--camera-name", "left")  # fmt: skip
    assert res.returncode == 0, res.stderr
    msg = read_ros_camera_info(intr.with_name("intrinsics_camera_info.yaml"))
    assert (msg["camera_name"], msg["width"], msg["height"]) == ("left", 640, 480)
    K = np.array(yaml.safe_load(intr.read_text())["camera_matrix"])
    np.testing.assert_allclose(msg["K"].reshape(3, 3), K)
    fs = cv2.FileStorage(str(intr.with_name("intrinsics_opencv.yaml")), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), K)
    assert int(fs.getNode("image_width").real()) == 640
    assert fs.getNode("distortion_coefficients").mat().shape == (1, 5)
    fs.release()
    # the repeated form is the same list; a bad item is refused before any work
    both = ("ros", "opencv")
    assert parse_list_option(["ros,opencv"], both, "--export") == both
    assert parse_list_option(["ros", "opencv", "ros"], both, "--export") == both
    bad = acscal("intrinsics", imgs, *board, "-o", tmp_path / "b.yaml", "--export", "ros,urdf")
    assert bad.returncode == 2 and "'urdf' is not one of ros, opencv" in bad.stderr
    tum = tmp_path / "left.tum"
    shutil.copy(intr.with_name("intrinsics.detections.npz"), tmp_path / "p.detections.npz")
    res = acscal(
        "poses", imgs, "--intrinsics", intr, *board, "-o", tmp_path / "p.npz", "--tum", tum
    )
    assert res.returncode == 0, res.stderr
    traj = file_interface.read_tum_trajectory_file(str(tum))
    assert traj.num_poses == 13 and np.all(traj.positions_xyz[:, 2] < 0)
