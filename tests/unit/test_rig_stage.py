"""The rig stage: a config with fixed-joint sessions of a hinge and a ball as priors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acs_cli.errors import InputError
from acs_cli.io.rig import RigArtifact
from acs_cli.io.trajectory import write_tum
from acs_cli.stages.rig import RigRun, RigRunConfig, parse_rig_config, run_rig
from sample_data_gen.rig_sim import fixed_joint_motion, rig_recording

JOINTS = (("j01", ("cam0", "cam1"), "ball"), ("h12", ("cam1", "cam2"), "hinge"))


def test_fixed_joint_sessions_become_priors(tmp_path: Path, rng: np.random.Generator) -> None:
    rec = rig_recording(rng, 60, joints=JOINTS, sigma_rot_deg=0.5, sigma_trans=0.02)
    for c, T in rec.T_wc_c.items():
        write_tum(tmp_path / f"{c}.tum", rec.timestamps, T)
    e01, h12 = rec.edges["j01"], rec.edges["h12"]
    assert h12.axis_p is not None and h12.axis_q is not None
    sessions = {
        "fj01_cam0": fixed_joint_motion(rng, e01.o_p, None),
        "fj12_cam1": fixed_joint_motion(rng, h12.o_p, h12.axis_p),
        "fj12_cam2": fixed_joint_motion(rng, h12.o_q, h12.axis_q),
    }
    for name, T in sessions.items():
        write_tum(tmp_path / f"{name}.tum", np.arange(T.shape[0]) * 0.1, T)
    text = (
        "schema_version: 2\noutput: out\ncameras:\n"
        "  cam0: {poses: cam0.tum}\n  cam1: {poses: cam1.tum}\n  cam2: {poses: cam2.tum}\n"
        "joints:\n"
        "  j01: {between: [cam0, cam1], type: ball, fixed_joint: {cam0: fj01_cam0.tum}}\n"
        "  h12: {between: [cam1, cam2], type: hinge,\n"
        "        fixed_joint: {cam1: fj12_cam1.tum, cam2: fj12_cam2.tum}}\n"
    )
    (tmp_path / "rig.yaml").write_text(text, encoding="utf-8")
    cfg = parse_rig_config(__import__("yaml").safe_load(text), tmp_path / "rig.yaml")
    with_priors = run_rig(cfg)
    assert "fixed_joint_h12_cam2" in with_priors.artifact.header["inputs"]
    plain = run_rig(parse_rig_config(
        __import__("yaml").safe_load(text.replace(", fixed_joint: {cam0: fj01_cam0.tum}", "")
                                     .replace(",\n        fixed_joint: {cam1: fj12_cam1.tum, "
                                              "cam2: fj12_cam2.tum}", "")),
        tmp_path / "rig.yaml",
    ), output=tmp_path / "plain.yaml")  # fmt: skip
    art = RigArtifact.load(tmp_path / "out" / "rig.yaml")

    def axis_err(a: RigArtifact) -> float:
        u = a.joints["h12"].axis_in["cam1"]
        return float(np.degrees(np.arccos(min(1.0, abs(float(u @ h12.axis_p))))))

    # the sessions' priors sharpen the joint: the ball's centre and the hinge's axis
    err_prior = np.linalg.norm(art.joints["j01"].position_in["cam0"] - e01.o_p)
    err_plain = np.linalg.norm(plain.artifact.joints["j01"].position_in["cam0"] - e01.o_p)
    assert err_prior < 0.01 and err_prior < err_plain
    assert axis_err(art) < 0.3 and axis_err(art) <= axis_err(plain.artifact) + 0.05
    std_prior = art.joints["h12"].axis_std_deg_in["cam1"]
    assert std_prior < plain.artifact.joints["h12"].axis_std_deg_in["cam1"]


def test_fixed_joint_of_a_camera_with_unknown_scale_is_refused(tmp_path: Path) -> None:
    text = (
        "schema_version: 2\noutput: out\ncameras:\n"
        "  cam0: {poses: cam0.tum}\n  cam1: {poses: cam1.tum, scale: unknown}\n"
        "joints:\n  j01: {between: [cam0, cam1], type: ball, fixed_joint: {cam1: f.tum}}\n"
    )
    cfg = parse_rig_config(__import__("yaml").safe_load(text), tmp_path / "rig.yaml")
    with pytest.raises(InputError, match=r"joints\.j01\.fixed_joint\.cam1: .*metric"):
        run_rig(cfg, output=tmp_path / "x.yaml")


def test_index_pairing_of_unequal_lengths_is_warned(tmp_path: Path) -> None:
    from acs_cli.io.trajectory import Trajectory
    from acs_cli.stages.rig import tracks_on_timeline

    text = (
        "schema_version: 2\noutput: out\npair_by: index\ncameras:\n"
        "  a: {poses: a.txt}\n  b: {poses: b.txt}\n"
        "joints:\n  j: {between: [a, b], type: ball}\n"
    )
    cfg = parse_rig_config(__import__("yaml").safe_load(text), tmp_path / "rig.yaml")
    eye = np.broadcast_to(np.eye(4), (20, 4, 4))
    trajs = {
        "a": Trajectory(np.arange(20.0), eye.copy(), "a.txt", "kitti", False),
        "b": Trajectory(np.arange(17.0), eye[:17].copy(), "b.txt", "kitti", False),
    }
    tracks, slots, _rows, warnings = tracks_on_timeline(cfg, trajs)
    assert slots.size == 20 and int(tracks["b"].valid.sum()) == 17
    assert any("different numbers of poses (a: 20, b: 17)" in w for w in warnings)


def _board_camera_files(tmp_path: Path) -> tuple[dict[str, Path], Path]:
    """Poses NPZs with corners (and their intrinsics files) of a simulated 2-camera rig,
    with a few frames dropped from one camera (so that rows and instants differ)."""
    from sample_data_gen.rig_sim import rig_corner_recording
    from sample_data_gen.writer import write_corner_poses

    joints = (("j", ("cam0", "cam1"), "ball"),)
    rec = rig_corner_recording(np.random.default_rng(3), 60, joints=joints)
    return write_corner_poses(tmp_path, rec, {"cam1": [5, 6, 20]}), tmp_path


def test_a_rig_of_board_cameras_is_bundle_adjusted_and_a_mixed_one_is_warned(
    tmp_path: Path,
) -> None:
    from acs_cli.io.trajectory import read_trajectory

    files, _ = _board_camera_files(tmp_path)
    text = (
        "schema_version: 2\noutput: out\ncameras:\n  cam0: {poses: cam0.npz}\n"
        "  cam1: {poses: cam1.npz}\njoints:\n  j: {between: [cam0, cam1], type: ball}\n"
    )

    def config(name: str, body: str) -> RigRunConfig:
        (tmp_path / name).write_text(body, encoding="utf-8")
        return parse_rig_config(__import__("yaml").safe_load(body), tmp_path / name)

    run = run_rig(config("rig.yaml", text))
    assert set(run.artifact.bundle_adjustment) == {"cam0", "cam1"}
    assert all(b.rms_px < 0.4 for b in run.artifact.bundle_adjustment.values())
    loaded = RigArtifact.load(tmp_path / "out" / "rig.yaml")
    assert "bundle adjustment" in loaded.header["method"]
    # the trajectories hold the bundle's per-frame fit where it adjusted, and say so
    head = (tmp_path / "out" / "trajectories" / "j.tum").read_text().splitlines()[1]
    assert "bundle adjustment's per-frame fit" in head, head
    # the same rig with bundle: false is solved from poses, with no section
    off = config("off.yaml", text + "bundle: false\n")
    assert not run_rig(off, output=tmp_path / "off.yaml").artifact.bundle_adjustment
    # a camera given as a TUM file carries no corners: a body with poses only in the bundle
    # (issue 19), its pose noise fitted and cam0's board placed in its world
    t1 = read_trajectory(files["cam1"])
    write_tum(tmp_path / "cam1.tum", t1.timestamps, t1.T_world_cam)
    mixed = config("mixed.yaml", text.replace("cam1.npz", "cam1.tum"))
    res = run_rig(mixed, output=tmp_path / "mixed.yaml")
    assert set(res.artifact.bundle_adjustment) == {"cam0"}, res.warnings
    po = res.artifact.cameras["cam1"].pose_only
    assert po is not None and set(po.T_world_board) == {"cam0"}
    assert 0 < po.sigma_translation < 0.05 and 0 < po.sigma_rotation_deg < 2
    back = RigArtifact.load(tmp_path / "mixed.yaml").cameras["cam1"].pose_only
    assert back is not None and back.sigma_translation == pytest.approx(po.sigma_translation)
    np.testing.assert_allclose(back.T_world_board["cam0"], po.T_world_board["cam0"], atol=1e-9)
    # a joint prior (metres, with its std) is fused with the corners by the bundle (issue
    # 19): a point given 5 mm off the corners' (std 2 mm) with a 0.5 mm std draws the joint
    # to within 0.3 mm of it (the weighted mean's share), the std below the prior's
    o = run.artifact.joints["j"].position_in["cam0"] + [0.005, 0.0, 0.0]
    prior = text.replace(
        "type: ball}",
        f"type: ball, position_in: {{cam0: [{o[0]}, {o[1]}, {o[2]}]}}, position_std: 0.0005}}",
    )
    res = run_rig(config("prior.yaml", prior), output=tmp_path / "prior.yaml.out")
    assert set(res.artifact.bundle_adjustment) == {"cam0", "cam1"}, res.warnings
    got = res.artifact.joints["j"]
    assert np.linalg.norm(got.position_in["cam0"] - o) < 0.0005
    assert np.all(got.position_std_in["cam0"] < 0.0005)


def test_recordings_without_frames_in_the_bundle_do_not_stop_it(tmp_path: Path) -> None:
    """A board-camera rig's general recording with a recording that holds its joint still
    (TUM sessions, no corners: Algorithm II's priors) or with a recording of one camera
    (no joint it moves): neither recording's frames enter the bundle, which runs on the
    general recording's corners (the first made both cameras pose-only bodies with no
    bundle at all, the second's boards left the bundle singular: refused)."""
    import yaml

    from sample_data_gen.rig_sim import rig_corner_recording
    from sample_data_gen.writer import write_corner_poses

    rng = np.random.default_rng(3)
    rec = rig_corner_recording(rng, 60, joints=(("j", ("cam0", "cam1"), "ball"),))
    for d in ("gen", "solo"):
        (tmp_path / d).mkdir()
    write_corner_poses(tmp_path / "gen", rec)
    write_corner_poses(tmp_path / "solo", rig_corner_recording(rng, 30, joints=(JOINTS[0],)))
    e = rec.rig.edges["j"]
    for c, o in (("cam0", e.o_p), ("cam1", e.o_q)):
        T = fixed_joint_motion(rng, o)
        write_tum(tmp_path / f"fixed_{c}.tum", np.arange(T.shape[0]) * 0.1, T)
    head = (
        "schema_version: 2\noutput: out\nreference: {camera: cam0, recording: general}\n"
        "joints:\n  j: {between: [cam0, cam1], type: ball}\nrecordings:\n  general:\n"
        "    cameras: {cam0: {poses: gen/cam0.npz}, cam1: {poses: gen/cam1.npz}}\n"
    )
    for name, other in (
        ("held", "    fixed_joints: [j]\n"
                 "    cameras: {cam0: {poses: fixed_cam0.tum}, cam1: {poses: fixed_cam1.tum}}\n"),
        ("solo", "    cameras: {cam1: {poses: solo/cam1.npz}}\n"),
    ):  # fmt: skip
        text = head + f"  {name}:\n" + other
        (tmp_path / f"{name}.yaml").write_text(text, encoding="utf-8")
        cfg = parse_rig_config(yaml.safe_load(text), tmp_path / f"{name}.yaml")
        run = run_rig(cfg, output=tmp_path / f"{name}_rig.yaml")
        assert set(run.artifact.bundle_adjustment) == {"cam0", "cam1"}, (name, run.warnings)
        assert not any("bundle" in w for w in run.warnings), (name, run.warnings)
        b = run.artifact.bundle_adjustment["cam1"]
        assert b.frames == run.artifact.bundle_adjustment["cam0"].frames <= 60, name
        j = run.artifact.joints["j"]
        err = np.linalg.norm(j.position_in["cam0"] - e.o_p)
        assert err < 4 * np.linalg.norm(j.position_std_in["cam0"]), (name, err)


def test_a_recording_the_bundle_does_not_take_keeps_the_pose_based_rig(tmp_path: Path) -> None:
    """A recording whose bodies are two parts of the rig (cam0 absent from a star's second
    recording): the pose-based solve takes it, the bundle adjustment does not, and the run
    keeps the pose-based estimate with a warning (it failed with the bundle's InputError)."""
    import yaml

    from sample_data_gen.rig_sim import rig_corner_recording
    from sample_data_gen.writer import write_corner_poses

    joints = (("r01", ("cam0", "cam1"), "rigid"), ("r02", ("cam0", "cam2"), "rigid"),
              ("b13", ("cam1", "cam3"), "ball"), ("b24", ("cam2", "cam4"), "ball"))  # fmt: skip
    n = 100
    rec = rig_corner_recording(np.random.default_rng(5), n, joints=joints)
    for name, out in {"all": range(n // 2, n), "part": range(n // 2)}.items():
        (tmp_path / name).mkdir()
        write_corner_poses(
            tmp_path / name, rec, drop={c: list(out) for c in rec.rig.topology.cameras}
        )

    def cams(r: str, cs: list[str]) -> str:
        return "{" + ", ".join(f"{c}: {{poses: {r}/{c}.npz}}" for c in cs) + "}"

    text = (
        "schema_version: 2\noutput: out\nreference: {camera: cam0, recording: all}\n"
        f"recordings:\n  all:\n    cameras: {cams('all', [f'cam{i}' for i in range(5)])}\n"
        f"  part:\n    cameras: {cams('part', [f'cam{i}' for i in range(1, 5)])}\njoints:\n"
        + "".join(f"  {j}: {{between: [{a}, {b}], type: {t}}}\n" for j, (a, b), t in joints)
    )
    (tmp_path / "rig.yaml").write_text(text, encoding="utf-8")
    run = run_rig(parse_rig_config(yaml.safe_load(text), tmp_path / "rig.yaml"))
    assert not run.artifact.bundle_adjustment
    assert any(
        w.startswith("no bundle adjustment of the rig: recordings.part: bodies cam1, cam2")
        for w in run.warnings
    ), run.warnings


def test_a_camera_posed_in_two_models_is_not_bundle_adjusted(tmp_path: Path) -> None:
    """cam1 of a chain from two recordings, its knee recording's poses solved with rational
    intrinsics and its hip recording's with pinhole ones: the bundle, which fits one set of
    intrinsics per camera, is not run, and says why (it fitted the knee's corners with the
    hip's pinhole model, and reported the hip's intrinsics file only)."""
    import dataclasses

    import yaml

    from acs_cli.io.intrinsics import IntrinsicsArtifact
    from sample_data_gen.rig_sim import rig_corner_recording
    from sample_data_gen.writer import write_corner_poses

    joints = (("hip", ("cam0", "cam1"), "ball"), ("knee", ("cam1", "cam2"), "hinge"))
    n = 160
    rec = rig_corner_recording(np.random.default_rng(5), n, joints=joints)
    for name, out in {"hip": range(n // 2, n), "knee": range(n // 2)}.items():
        (tmp_path / name).mkdir()
        write_corner_poses(
            tmp_path / name, rec, drop={c: list(out) for c in rec.rig.topology.cameras}
        )
    path = tmp_path / "knee" / "cam1_intrinsics.yaml"
    pinhole = IntrinsicsArtifact.load(path)
    rational = dataclasses.replace(
        pinhole,
        model="rational",
        distortion=np.concatenate([pinhole.distortion, np.zeros(3)]),
        distortion_names=["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
    )
    rational.save(path)
    text = (
        "schema_version: 2\noutput: out\nreference: {camera: cam0, recording: hip}\n"
        "recordings:\n"
        "  hip:\n    cameras: {cam0: {poses: hip/cam0.npz}, cam1: {poses: hip/cam1.npz}}\n"
        "  knee:\n    cameras: {cam1: {poses: knee/cam1.npz}, cam2: {poses: knee/cam2.npz}}\n"
        "joints:\n  hip: {between: [cam0, cam1], type: ball}\n"
        "  knee: {between: [cam1, cam2], type: hinge}\n"
    )
    (tmp_path / "rig.yaml").write_text(text, encoding="utf-8")
    run = run_rig(parse_rig_config(yaml.safe_load(text), tmp_path / "rig.yaml"))
    assert not run.artifact.bundle_adjustment
    assert (
        "no bundle adjustment of the rig: camera cam1's recordings were posed with different "
        "camera models (pinhole in hip/cam1, rational in knee/cam1); calibrate it in one model"
    ) in run.warnings, run.warnings


def test_rig_clock_offsets_are_estimated_and_warned_about(tmp_path: Path) -> None:
    """Cameras on separate clocks (issue 10): with estimate_time_offset each camera's offset
    to the reference is estimated and its poses interpolated; without it, the joints whose
    cameras fit clearly better shifted by a frame are named."""
    joints = (("j01", ("cam0", "cam1"), "ball"), ("r02", ("cam0", "cam2"), "rigid"))
    rec = rig_recording(
        np.random.default_rng(4), 150, joints=joints, smooth=True,
        time_offsets={"cam1": 0.031}, sigma_rot_deg=0.1, sigma_trans=0.005,
        max_rotation_deg=60.0, max_articulation_deg=40.0, translation_range=1.0,
    )  # fmt: skip
    for c, T in rec.T_wc_c.items():
        write_tum(tmp_path / f"{c}.tum", 50.0 + rec.timestamps, T)
    body = (
        "schema_version: 2\noutput: out\ncameras:\n"
        + "".join(f"  {c}: {{poses: {c}.tum}}\n" for c in rec.topology.cameras)
        + "joints:\n  j01: {between: [cam0, cam1], type: ball}\n"
        "  r02: {between: [cam0, cam2], type: rigid}\n"
    )

    def config(name: str, text: str) -> RigRunConfig:
        (tmp_path / name).write_text(text, encoding="utf-8")
        return parse_rig_config(__import__("yaml").safe_load(text), tmp_path / name)

    plain = run_rig(config("plain.yaml", body), output=tmp_path / "plain_rig.yaml")
    assert any(w.startswith("joint j01: shifting cam1's timestamps by +33.3 ms") for w in
               plain.warnings), plain.warnings  # fmt: skip
    assert not any("joint r02" in w for w in plain.warnings)
    run = run_rig(config("offset.yaml", body + "estimate_time_offset: true\nmax_offset: 0.06\n"))
    cams = RigArtifact.load(tmp_path / "out" / "rig.yaml").cameras
    assert cams["cam0"].time_offset_s == 0.0
    off, std = cams["cam1"].time_offset_s, cams["cam1"].time_offset_s_std
    assert off is not None and std is not None
    assert abs(off - 0.031) < 1.5e-3 and abs(off - 0.031) < 4 * std, (off, std)
    assert abs(cams["cam2"].time_offset_s or 0.0) < 1.5e-3
    # the timeline starts where every camera is covered: frame 0 is the recording's first
    truth = rec.T_cam_ref(0)
    for c in ("cam1", "cam2"):
        err = np.linalg.norm(run.artifact.cameras[c].T_cam_ref[:3, 3] - truth[c][:3, 3])
        assert err < 0.05, (c, err)
    assert any("interpolated" in w for w in run.warnings)


_SFM_RIG = (
    "schema_version: 2\noutput: out\n{extra}cameras:\n"
    "  a: {{images: imgs/a, front_end: sfm{a}}}\n  b: {{poses: b.tum}}\n"
    "joints:\n  j: {{between: [a, b], type: ball}}\n"
)


@pytest.mark.parametrize(
    ("a", "extra", "key"),
    [
        (", scale: known", "", "cameras.a.scale"),
        (", front_end: slam", "", "cameras.a.front_end"),
        ("", "sfm: {matching: fuzzy}\n", "sfm.matching"),
        ("", "sfm: {max_features: 3}\n", "sfm.max_features"),
        ("", "sfm: {colour: true}\n", "sfm"),
    ],
)
def test_markerless_cameras_are_checked(tmp_path: Path, a: str, extra: str, key: str) -> None:
    doc = __import__("yaml").safe_load(_SFM_RIG.format(a=a, extra=extra))
    with pytest.raises(InputError, match=key.replace(".", r"\.")):
        parse_rig_config(doc, tmp_path / "rig.yaml")


def test_markerless_cameras_plan_an_sfm_stage(tmp_path: Path) -> None:
    from acs_cli.stages.run import _plan_rig

    text = _SFM_RIG.format(a=", intrinsics: a.yaml", extra="sfm: {max_features: 2048}\n")
    cfg = parse_rig_config(__import__("yaml").safe_load(text), tmp_path / "rig.yaml")
    spec = cfg.cameras["a"]
    assert spec.front_end == "sfm" and spec.unknown_scale  # SfM is up to scale
    assert spec.intrinsics == tmp_path / "a.yaml" and cfg.board is None  # no board needed
    stages, _intrinsics = _plan_rig(cfg)
    sfm = [s for s in stages if s.stage == "sfm a"]
    assert len(sfm) == 1 and sfm[0].options == {"front_end": "sfm", "max_features": 2048}
    assert sfm[0].inputs == {"images": tmp_path / "imgs/a", "intrinsics": tmp_path / "a.yaml"}
    assert sfm[0].outputs == [tmp_path / "out" / "cam_a" / "poses.npz"]
    board = text.replace(", front_end: sfm, intrinsics: a.yaml", ", intrinsics: a.yaml")
    with pytest.raises(InputError, match=r"cameras\.a\.intrinsics"):
        parse_rig_config(__import__("yaml").safe_load(board), tmp_path / "rig.yaml")


def _hinge_rig_config(tmp_path: Path, rng: np.random.Generator) -> str:
    """A three-camera rig's recording written to ``tmp_path`` (ball j01, hinge h12) and its
    config, with ``%s`` where the hinge's own keys go."""
    rec = rig_recording(rng, 40, joints=JOINTS, sigma_rot_deg=0.3, sigma_trans=0.01)
    for c, T in rec.T_wc_c.items():
        write_tum(tmp_path / f"{c}.tum", rec.timestamps, T)
    return (
        "schema_version: 2\noutput: out\ncameras:\n"
        "  cam0: {poses: cam0.tum}\n  cam1: {poses: cam1.tum}\n  cam2: {poses: cam2.tum}\n"
        "joints:\n  j01: {between: [cam0, cam1], type: ball}\n"
        "  h12: {between: [cam1, cam2], type: hinge%s}\n"
    )


def test_a_hinge_axis_points_the_way_the_config_says(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    """Issue 22, item 2: ``joints.<name>.axis`` picks the sign of a hinge's axis (a direction
    in one of its bodies, or towards a named body); the angle range turns with it."""
    import yaml

    base = _hinge_rig_config(tmp_path, rng)

    def solve(axis: str, name: str) -> tuple[RigArtifact, list[str]]:
        text = base % axis
        (tmp_path / "rig.yaml").write_text(text, encoding="utf-8")
        cfg = parse_rig_config(yaml.safe_load(text), tmp_path / "rig.yaml")
        run = run_rig(cfg, output=tmp_path / f"{name}.yaml")
        return run.artifact, run.artifact.warnings

    plain, _ = solve("", "plain")
    u = plain.joints["h12"].axis_in["cam2"]
    # the default: largest component in the first body (cam1) positive
    u1 = plain.joints["h12"].axis_in["cam1"]
    assert u1[int(np.argmax(np.abs(u1)))] > 0
    for d, flipped in ((-u, True), (u, False)):
        want = f", axis: {{direction: [{d[0]:.6f}, {d[1]:.6f}, {d[2]:.6f}], in: cam2}}"
        art, warnings = solve(want, "given")
        sign = -1.0 if flipped else 1.0
        for c in ("cam1", "cam2"):
            np.testing.assert_allclose(
                art.joints["h12"].axis_in[c], sign * plain.joints["h12"].axis_in[c]
            )
        lo, hi = plain.joints["h12"].angle_range_deg
        rng_deg = art.joints["h12"].angle_range_deg
        assert rng_deg == pytest.approx((-hi, -lo) if flipped else (lo, hi), abs=1e-6)
        assert not any("barely tells" in w for w in warnings)
    # the URDF follows: the revolute joint's axis turns round with it
    import xml.etree.ElementTree as ET

    from acs_cli.stages.export import run_rig_export

    def urdf_axis(name: str) -> np.ndarray:
        out = tmp_path / f"{name}.urdf"
        run_rig_export(tmp_path / f"{name}.yaml", out, "urdf")
        joint = next(j for j in ET.parse(out).getroot().iter("joint") if j.get("name") == "h12")
        return np.array([float(v) for v in joint.find("axis").get("xyz").split()])  # type: ignore[union-attr]

    np.testing.assert_allclose(urdf_axis("given"), urdf_axis("plain"), atol=1e-9)  # u: kept
    solve(f", axis: {{direction: [{-u[0]:.6f}, {-u[1]:.6f}, {-u[2]:.6f}], in: cam2}}", "flip")
    np.testing.assert_allclose(urdf_axis("flip"), -urdf_axis("plain"), atol=1e-9)
    # towards a body: the axis points from the joint to that body's origin
    art, _ = solve(", axis: {towards: cam0}", "towards")
    T1 = art.cameras["cam1"].T_cam_ref
    T0 = art.cameras["cam0"].T_cam_ref
    to0 = (T1 @ np.linalg.inv(T0))[:3, 3] - art.joints["h12"].position_in["cam1"]
    assert float(art.joints["h12"].axis_in["cam1"] @ to0) > 0
    # across the axis: a warning that the direction barely tells
    across = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
    axis = f", axis: {{direction: [{across[0]:.9f}, {across[1]:.9f}, {across[2]:.9f}], in: cam2}}"
    _, warnings = solve(axis, "across")
    assert any("joint h12: its axis is" in w and "barely tells" in w for w in warnings)


def test_a_hinge_point_is_reported_where_the_config_says(
    tmp_path: Path, rng: np.random.Generator
) -> None:
    """Issue 22, item 2: ``joints.<name>.point: {nearest, in}`` reports a hinge's point as the
    axis point nearest a point given in one of its bodies: the same physical point in both,
    its std propagated from the point and the axis; rig.yaml, the joint's trajectory,
    ``acscal trajectory``'s joint and the URDF follow; the verdict does not move."""
    import xml.etree.ElementTree as ET

    import yaml

    from acs_cli.core import se3
    from acs_cli.core.rig import hinge_point_from_nearest
    from acs_cli.io.trajectory import read_trajectory
    from acs_cli.stages.export import run_rig_export
    from acs_cli.stages.rig import trajectories_from_rig

    base = _hinge_rig_config(tmp_path, rng)

    def solve(extra: str, name: str) -> tuple[RigRun, Path]:
        text = base % extra
        (tmp_path / "rig.yaml").write_text(text, encoding="utf-8")
        cfg = parse_rig_config(yaml.safe_load(text), tmp_path / "rig.yaml")
        out = tmp_path / name / "rig.yaml"
        return run_rig(cfg, output=out), out

    plain_run, plain_file = solve("", "plain")
    plain = plain_run.artifact
    h = plain.joints["h12"]
    u2 = h.axis_in["cam2"]
    given = h.position_in["cam2"] + 1.5 * u2 + np.cross(u2, [0.0, 0.0, 0.2])
    g = ", ".join(f"{v:.9f}" for v in given)
    run, moved_file = solve(f", point: {{nearest: [{g}], in: cam2}}", "moved")
    moved = run.artifact
    m = moved.joints["h12"]
    T_ref = {c: np.linalg.inv(moved.cameras[c].T_cam_ref) for c in ("cam1", "cam2")}
    # one physical point (at the reference instant), on the axis, nearest the point given
    np.testing.assert_allclose(
        se3.transform_points(T_ref["cam1"], m.position_in["cam1"]),
        se3.transform_points(T_ref["cam2"], m.position_in["cam2"]),
        atol=1e-3,
    )
    for c in ("cam1", "cam2"):
        step = m.position_in[c] - h.position_in[c]
        np.testing.assert_allclose(np.cross(step, h.axis_in[c]), 0.0, atol=1e-12)
        assert float(step @ h.axis_in[c]) == pytest.approx(1.5, abs=1e-6)
    assert float((given - m.position_in["cam2"]) @ u2) == pytest.approx(0.0, abs=1e-9)
    # the std: propagated from the geometry (point, axis, their cross-covariance), not
    # copied: larger 1.5 units along the axis
    e = run.estimate.edges["h12"]
    _, C = hinge_point_from_nearest(e.geometry, e.geometry_covariance, 1, given)
    np.testing.assert_allclose(m.position_std_in["cam1"], np.sqrt(np.diag(C)[:3]), rtol=1e-6)
    np.testing.assert_allclose(m.position_std_in["cam2"], np.sqrt(np.diag(C)[3:]), rtol=1e-6)
    for c in ("cam1", "cam2"):
        assert np.linalg.norm(m.position_std_in[c]) > np.linalg.norm(h.position_std_in[c])
    # the rest is the same rig: axes, angles, the other joint, the verdict, the warnings
    for c in ("cam1", "cam2"):
        np.testing.assert_allclose(m.axis_in[c], h.axis_in[c])
    assert m.angle_range_deg == h.angle_range_deg
    for c in ("cam0", "cam1"):
        np.testing.assert_allclose(
            moved.joints["j01"].position_in[c], plain.joints["j01"].position_in[c]
        )
    assert moved.verdict == plain.verdict and moved.warnings == plain.warnings
    assert "the axis point nearest" in moved.header["frames"]["position_in"]
    assert "nearest" not in plain.header["frames"]["position_in"]
    # the joint's trajectory (and acscal trajectory's): moved by the step in cam1's frame
    step1 = m.position_in["cam1"] - h.position_in["cam1"]
    tp = read_trajectory(plain_file.parent / "trajectories" / "h12.tum").T_world_cam
    tm = read_trajectory(moved_file.parent / "trajectories" / "h12.tum").T_world_cam
    np.testing.assert_allclose(tm[:, :3, 3] - tp[:, :3, 3], tp[:, :3, :3] @ step1, atol=1e-6)
    trajs = {c: read_trajectory(tmp_path / f"{c}.tum") for c in ("cam0", "cam1", "cam2")}
    _, Jp = trajectories_from_rig(plain, trajs)["h12"]
    _, Jm = trajectories_from_rig(moved, trajs)["h12"]
    np.testing.assert_allclose(Jm[:, :3, 3] - Jp[:, :3, 3], Jp[:, :3, :3] @ step1, atol=1e-9)

    # the URDF: the revolute joint's origin (in its parent body, cam1's axes) moves with it
    def urdf_origin(rig_file: Path) -> np.ndarray:
        out = rig_file.parent / "rig.urdf"
        run_rig_export(rig_file, out, "urdf")
        joint = next(j for j in ET.parse(out).getroot().iter("joint") if j.get("name") == "h12")
        return np.array([float(v) for v in joint.find("origin").get("xyz").split()])  # type: ignore[union-attr]

    np.testing.assert_allclose(urdf_origin(moved_file) - urdf_origin(plain_file), step1, atol=1e-3)
