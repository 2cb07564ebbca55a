"""``--joint-type`` on ``acscal relpose`` and ``acscal joint --overlap`` (issue 19, item 4):
the two-body rig declared a hinge or a rigid mount, through the real CLI on simulated pairs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.joint import JointArtifact, JointSection
from acs_cli.io.relpose import RelposeArtifact, load_joint_artifact
from acs_cli.io.trajectory import write_tum
from sample_data_gen.acs_sim import add_pose_noise, near_hinge_pair
from sample_data_gen.rig_sim import RigRecording, rig_recording

SIGMA_ROT_DEG, SIGMA_TRANS = 0.1, 0.002


def _pair(root: Path, jtype: str, seed: int) -> tuple[RigRecording, dict[str, Path]]:
    """A two-camera rig of ``jtype`` (cameras a, b; general motion): each camera's noisy
    trajectory in its own world (``a``, ``b``) and both in the physical world (``wa``,
    ``wb``, noisy too), as TUM files."""
    rng = np.random.default_rng(seed)
    rec = rig_recording(
        rng, 80, joints=(("j", ("a", "b"), jtype),), reference="a",
        sigma_rot_deg=SIGMA_ROT_DEG, sigma_trans=SIGMA_TRANS,
    )  # fmt: skip
    files = {}
    for key, T in (
        ("a", rec.T_wc_c["a"]),
        ("b", rec.T_wc_c["b"]),
        ("wa", add_pose_noise(rng, rec.T_W_c["a"], SIGMA_ROT_DEG, SIGMA_TRANS)),
        ("wb", add_pose_noise(rng, rec.T_W_c["b"], SIGMA_ROT_DEG, SIGMA_TRANS)),
    ):
        files[key] = root / f"{jtype}_{key}.tum"
        write_tum(files[key], rec.timestamps, T)
    return rec, files


@pytest.fixture(scope="module")
def hinge(tmp_path_factory: pytest.TempPathFactory) -> tuple[RigRecording, dict[str, Path]]:
    return _pair(tmp_path_factory.mktemp("hinge"), "hinge", 7)


@pytest.fixture(scope="module")
def rigid(tmp_path_factory: pytest.TempPathFactory) -> tuple[RigRecording, dict[str, Path]]:
    return _pair(tmp_path_factory.mktemp("rigid"), "rigid", 8)


def _angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    """The angle between two lines (directions up to sign), degrees."""
    c = abs(float(u @ v)) / (np.linalg.norm(u) * np.linalg.norm(v))
    return float(np.degrees(np.arccos(min(1.0, c))))


def _check_pose(art: RelposeArtifact, T_true: np.ndarray, k: float = 5.0) -> None:
    """``T_b_a`` within ``k`` of its stds of the truth (right rotation perturbation, t)."""
    T = np.asarray(art.relative_pose.T_b_a)
    C = np.asarray(art.relative_pose.T_b_a_covariance)
    std = np.sqrt(np.diag(C))
    d_rot = se3.rotvec_from_matrix(T_true[:3, :3].T @ T[:3, :3])
    d_t = T[:3, 3] - T_true[:3, 3]
    assert np.all(np.abs(d_rot) < k * std[:3] + 1e-9), (d_rot, std[:3])
    assert np.all(np.abs(d_t) < k * std[3:] + 1e-9), (d_t, std[3:])


def _check_hinge_axes(joint: JointSection, rec: RigRecording) -> None:
    e = rec.edges["j"]
    assert joint.type == "hinge"
    assert e.axis_p is not None and e.axis_q is not None
    for axis, std, truth in (
        (joint.axis_in_a, joint.axis_in_a_std_deg, e.axis_p),
        (joint.axis_in_b, joint.axis_in_b_std_deg, e.axis_q),
    ):
        assert axis is not None and std is not None
        assert abs(np.linalg.norm(axis) - 1.0) < 1e-9
        assert _angle_deg(np.asarray(axis), truth) < 4.0 * std + 1e-6, (axis, truth, std)
    # the point on the axis nearest A's centre, and the same point in B
    for pos, cov, truth in (
        (joint.position_in_a, joint.covariance("a"), e.o_p),
        (joint.position_in_b, joint.covariance("b"), e.o_q),
    ):
        err = np.linalg.norm(np.asarray(pos) - truth)
        assert err < 5.0 * np.sqrt(np.trace(cov)) + 1e-9, (pos, truth)
    assert abs(float(np.asarray(joint.position_in_a) @ np.asarray(joint.axis_in_a))) < 1e-6


def test_relpose_self_calibrates_a_hinge(
    hinge: tuple[RigRecording, dict[str, Path]], tmp_path: Path
) -> None:
    rec, f = hinge
    out = tmp_path / "relpose.yaml"
    res = acscal(
        "relpose", "--self-calibrate", "--joint-type", "hinge",
        "--poses-a", f["a"], "--poses-b", f["b"], "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "joint.axis_in_a" in res.stdout
    art = RelposeArtifact.load(out)
    assert art.joint_type == "hinge"
    assert art.joint is not None
    _check_hinge_axes(art.joint, rec)
    _check_pose(art, rec.T_cam_ref(0)["b"])
    assert "declared a hinge" in str(art.header["method"])


def test_joint_overlap_locates_a_hinge_and_relpose_takes_it(
    hinge: tuple[RigRecording, dict[str, Path]], tmp_path: Path
) -> None:
    rec, f = hinge
    joint = tmp_path / "joint.yaml"
    res = acscal(
        "joint", "--overlap", "--joint-type", "hinge",
        "--poses-a", f["wa"], "--poses-b", f["wb"], "-o", joint,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    art = JointArtifact.load(joint)
    _check_hinge_axes(art.joint, rec)
    # as a ball, the same motion is refused: it bends about one axis only
    res = acscal(
        "joint", "--overlap", "--poses-a", f["wa"], "--poses-b", f["wb"], "-o", tmp_path / "b.yaml"
    )
    assert res.returncode != 0 and "axis" in res.stderr
    # the hinge's point as the prior of the relative pose
    out = tmp_path / "relpose.yaml"
    res = acscal(
        "relpose", "--joint", joint, "--joint-type", "hinge",
        "--poses-a", f["a"], "--poses-b", f["b"], "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    rel = RelposeArtifact.load(out)
    assert rel.joint is not None and rel.joint.axis_in_a is not None
    _check_pose(rel, rec.T_cam_ref(0)["b"])


def test_relpose_rigid_recovers_a_constant_pose(
    rigid: tuple[RigRecording, dict[str, Path]], tmp_path: Path
) -> None:
    rec, f = rigid
    poses = {}
    for k in (0, 40):
        out = tmp_path / f"relpose_{k}.yaml"
        res = acscal(
            "relpose", "--joint-type", "rigid", "--reference", str(k),
            "--poses-a", f["a"], "--poses-b", f["b"], "-o", out,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        art = RelposeArtifact.load(out)
        assert art.joint_type == "rigid"
        assert art.joint is None  # no joint point: no joint section
        assert "joint" not in out.read_text().split("relative_pose:")[1].split("quality:")[0]
        _check_pose(art, rec.T_cam_ref(k)["b"])
        poses[k] = art.relative_pose
    # one constant T_b_a whatever the reference instant (the truth's too)
    assert np.allclose(rec.T_cam_ref(0)["b"], rec.T_cam_ref(40)["b"])
    T0, T40 = np.asarray(poses[0].T_b_a), np.asarray(poses[40].T_b_a)
    std = np.sqrt(np.diag(np.asarray(poses[0].T_b_a_covariance)))
    assert np.degrees(np.linalg.norm(se3.rotvec_from_matrix(T0[:3, :3].T @ T40[:3, :3]))) < max(
        0.5 * np.degrees(std[:3].max()), 1e-6
    )
    assert np.linalg.norm(T0[:3, 3] - T40[:3, 3]) < max(0.5 * std[3:].max(), 1e-9)
    # its relpose.yaml is no joint for a later --joint
    with pytest.raises(InputError, match="rigid"):
        load_joint_artifact(tmp_path / "relpose_0.yaml")


def test_the_default_is_the_ball_joint_unchanged(tmp_path: Path) -> None:
    """``--joint-type ball`` writes what no option writes, byte for byte but the time."""
    ball = _pair(tmp_path, "ball", 9)[1]
    texts = []
    for extra in ((), ("--joint-type", "ball")):
        out = tmp_path / f"relpose{len(extra)}.yaml"
        res = acscal(
            "relpose", "--self-calibrate", *extra,
            "--poses-a", ball["a"], "--poses-b", ball["b"], "-o", out,
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        texts.append([ln for ln in out.read_text().splitlines() if not ln.startswith("created:")])
    assert texts[0] == texts[1]
    assert not any("joint_type" in ln or "axis_in" in ln for ln in texts[0])


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("joint", "--overlap", "--joint-type", "rigid"), "rigid pair has no joint point"),
        (("joint", "--fixed-joint", "--joint-type", "hinge"), "--joint-type applies to"),
        (("joint", "--overlap", "--joint-type", "hinge", "--method", "paper"), "ball joint only"),
        (("relpose", "--self-calibrate", "--joint-type", "hinge", "--method", "paper"),
         "ball joint only"),
    ],
)  # fmt: skip
def test_refusals_are_one_line_and_exit_2(
    hinge: tuple[RigRecording, dict[str, Path]],
    tmp_path: Path,
    args: tuple[str, ...],
    words: str,
) -> None:
    _, f = hinge
    a, b = (f["wa"], f["wb"]) if args[0] == "joint" else (f["a"], f["b"])
    res = acscal(*args, "--poses-a", a, "--poses-b", b, "-o", tmp_path / "out.yaml")
    assert res.returncode == 2, res.stderr
    assert words in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out.yaml").exists()


def test_rigid_refuses_a_joint_file(
    hinge: tuple[RigRecording, dict[str, Path]], tmp_path: Path
) -> None:
    _, f = hinge
    joint = tmp_path / "joint.yaml"
    res = acscal(
        "joint", "--overlap", "--joint-type", "hinge",
        "--poses-a", f["wa"], "--poses-b", f["wb"], "-o", joint,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    res = acscal(
        "relpose", "--joint", joint, "--joint-type", "rigid",
        "--poses-a", f["a"], "--poses-b", f["b"], "-o", tmp_path / "out.yaml",
    )  # fmt: skip
    assert res.returncode == 2
    assert "rigid joint has no joint point" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("jtype", ["hinge", "rigid"])
def test_unknown_scale_with_a_hinge_or_a_rigid_mount(
    jtype: str, request: pytest.FixtureRequest, tmp_path: Path
) -> None:
    """B's trajectory in its own units (0.4 per metre, a monocular SLAM's): the scale and
    ``T_b_a`` in B's units come out within their stds, as for a ball joint."""
    rec, f = request.getfixturevalue(jtype)
    T_b = rec.T_wc_c["b"].copy()
    T_b[:, :3, 3] *= 0.4
    scaled = tmp_path / "b_scaled.tum"
    write_tum(scaled, rec.timestamps, T_b)
    out = tmp_path / "relpose.yaml"
    calibrate = () if jtype == "rigid" else ("--self-calibrate",)
    res = acscal(
        "relpose", *calibrate, "--unknown-scale", "--joint-type", jtype,
        "--poses-a", f["a"], "--poses-b", scaled, "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "bundle adjustment" not in res.stderr  # TUM files: no corners to speak of
    art = RelposeArtifact.load(out)
    assert art.scale is not None and art.scale.phi_ba_std is not None
    assert abs(art.scale.phi_ba - 0.4) < 4 * art.scale.phi_ba_std, art.scale
    T_true = rec.T_cam_ref(0)["b"].copy()
    T_true[:3, 3] *= 0.4  # B's units
    _check_pose(art, T_true)
    if jtype == "hinge":
        assert art.joint is not None and art.joint.axis_in_a is not None


@pytest.mark.parametrize("jtype", ["hinge", "rigid"])
def test_a_clock_offset_with_a_hinge_or_a_rigid_mount(jtype: str, tmp_path: Path) -> None:
    """B's clock 13 ms late on smooth motion: ``--estimate-time-offset`` finds it within its
    std whatever the joint type, and the pose after it is within its stds."""
    rec = rig_recording(
        np.random.default_rng(3), 150, joints=(("j", ("a", "b"), jtype),), reference="a",
        smooth=True, time_offsets={"b": 0.013}, sigma_rot_deg=SIGMA_ROT_DEG,
        sigma_trans=SIGMA_TRANS,
    )  # fmt: skip
    f = {c: tmp_path / f"{c}.tum" for c in "ab"}
    for c, path in f.items():
        write_tum(path, rec.timestamps, rec.T_wc_c[c])
    out = tmp_path / "relpose.yaml"
    calibrate = () if jtype == "rigid" else ("--self-calibrate",)
    res = acscal(
        "relpose", *calibrate, "--joint-type", jtype, "--estimate-time-offset",
        "--max-offset", "0.1", "--poses-a", f["a"], "--poses-b", f["b"], "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    art = RelposeArtifact.load(out)
    offset = art.time_offset
    assert offset is not None and offset.time_offset_s_std is not None
    assert abs(offset.time_offset_s - 0.013) < 4 * offset.time_offset_s_std, offset
    # the reference instant: the first of A's frames B's shifted recording covers
    t_ref = art.relative_pose.reference_timestamp_a
    assert t_ref is not None
    k = int(np.argmin(np.abs(rec.timestamps - t_ref)))
    _check_pose(art, rec.T_cam_ref(k)["b"])


def test_a_hinge_that_wobbles_is_warned_about_in_the_pairs_words(tmp_path: Path) -> None:
    """A ball joint bending about one axis with 2 deg of wobble across it, declared a hinge:
    written (the misfit is under the refusal level) with the rig's type check as a warning,
    naming the pair's joint and option (it was computed and dropped)."""
    p = near_hinge_pair(np.random.default_rng(3), 120, wobble_deg=2.0)
    files = {}
    for key, T in (("a", p.T_w_a), ("b", p.T_w_b), ("bb", p.T_wb_b)):
        files[key] = tmp_path / f"{key}.tum"
        write_tum(files[key], p.timestamps, T)
    for args in (
        ("joint", "--overlap", "--poses-a", files["a"], "--poses-b", files["b"]),
        ("relpose", "--self-calibrate", "--poses-a", files["a"], "--poses-b", files["bb"]),
    ):
        res = acscal(*args, "--joint-type", "hinge", "-o", tmp_path / f"{args[0]}.yaml")
        assert res.returncode == 0, res.stderr
        warned = [w for w in res.stderr.splitlines() if "declared a hinge" in w]
        assert len(warned) == 1, res.stderr
        assert "the joint (A-B) is declared a hinge, but its axis moves by" in warned[0]
        assert "(--joint-type ball)" in warned[0] and "joint joint" not in warned[0]
