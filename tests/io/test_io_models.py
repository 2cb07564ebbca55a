"""Typed artifacts: round trips (save then load, equal), the keys written, validation on load
and the shared validators."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header
from acs_cli.io.base import Artifact, YamlArtifact
from acs_cli.io.intrinsics import BoardSpec, DroppedView, ImagesUsed, IntrinsicsArtifact
from acs_cli.io.joint import (
    BundleSection,
    FramesUsed,
    JointArtifact,
    JointQuality,
    JointSection,
    Pairing,
    PoseNoise,
)
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.relpose import (
    RelativePose,
    RelposeArtifact,
    RelposeQuality,
    Scale,
    load_joint_section,
)
from acs_cli.io.trajectory import Trajectory, read_trajectory
from acs_cli.io.validate import (
    as_covariance3,
    as_int,
    as_number,
    as_vector,
    listed_mask,
)

RNG = np.random.default_rng(5)


def _header(kind: str) -> dict[str, Any]:
    return make_header(kind, {}, method="test", units={"length": "m", "angles": "deg"}, frames={})


def _cov() -> np.ndarray:
    A = RNG.normal(size=(3, 3)) * 1e-3
    return A @ A.T


def _poses(n: int) -> np.ndarray:
    R = Rotation.random(n, random_state=RNG).as_matrix()
    return se3.transforms_from_rt(R, RNG.uniform(-1, 1, (n, 3))).reshape(n, 4, 4)


def _assert_same(a: Any, b: Any, path: str = "") -> None:
    """Deep equality of plain data (numbers within 1e-12)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), path
        for k in a:
            _assert_same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, abs=1e-12, nan_ok=True), path
    else:
        assert a == b, path


def _round_trip(art: YamlArtifact, tmp_path: Path) -> tuple[YamlArtifact, dict[str, Any]]:
    """Save, load, save again: the two files hold the same document."""
    first, second = tmp_path / "first.yaml", tmp_path / "second.yaml"
    art.save(first)
    loaded = type(art).load(first)
    loaded.save(second)
    doc1 = yaml.safe_load(first.read_text())
    doc2 = yaml.safe_load(second.read_text())
    _assert_same(doc1, doc2)
    assert first.read_text() == second.read_text()
    return loaded, doc1


def _intrinsics() -> IntrinsicsArtifact:
    K = np.array([[600.0, 0.0, 320.5], [0.0, 601.0, 240.25], [0.0, 0.0, 1.0]])
    return IntrinsicsArtifact(
        model="pinhole",
        image_size=(640, 480),
        camera_matrix=K,
        distortion=np.array([0.01, -0.02, 0.001, 0.0, 0.003]),
        distortion_names=["k1", "k2", "p1", "p2", "k3"],
        rms_px=0.12,
        per_view_rms_px={"a.png": 0.1, "b.png": 0.14},
        std={"fx": 0.5, "fy": 0.5, "cx": 0.3, "cy": 0.2, "distortion": [1e-3] * 5},
        board=BoardSpec(9, 6, 0.025),
        images=ImagesUsed(4, ["a.png", "b.png"], ["c.png"], [DroppedView("d.png", 3.5)]),
        detector="v1",
        detections_cache="intrinsics.detections.npz",
        exports={"ros": "intrinsics_camera_info.yaml"},
        warnings=["no board in 1 image(s): c.png"],
        header=_header("intrinsics"),
    )


def test_intrinsics_round_trip(tmp_path: Path) -> None:
    art = _intrinsics()
    loaded, doc = _round_trip(art, tmp_path)
    assert isinstance(loaded, IntrinsicsArtifact)
    assert list(doc)[8:] == [
        "model", "image_size", "camera_matrix", "distortion", "distortion_names", "rms_px",
        "per_view_rms_px", "std", "board", "target", "images", "detector", "detections_cache",
        "exports", "warnings",
    ]  # fmt: skip
    np.testing.assert_array_equal(loaded.camera_matrix, art.camera_matrix)
    np.testing.assert_array_equal(loaded.distortion, art.distortion)
    assert loaded.image_size == (640, 480) and loaded.board == art.board
    assert loaded.images == art.images and loaded.per_view_rms_px == art.per_view_rms_px
    assert loaded.source == str(tmp_path / "first.yaml")
    assert "fx 600.00 +- 0.5" in loaded.summary()


def test_intrinsics_minimal_file_and_errors(tmp_path: Path) -> None:
    p = tmp_path / "intrinsics.yaml"
    body = "camera_matrix: [[500, 0, 320], [0, 500, 240], [0, 0, 1]]\n"
    body += "distortion: [0, 0, 0, 0, 0]\nimage_size: [640, 480]\n"
    p.write_text("schema: acscal/intrinsics\nschema_version: 1\n" + body)
    art = IntrinsicsArtifact.load(p)
    assert art.model == "pinhole" and art.board is None and art.rms_px is None
    assert art.distortion_names == ["k1", "k2", "p1", "p2", "k3"]
    p.write_text(p.read_text().replace("distortion: [0, 0, 0, 0, 0]", "distortion: [0, 0]"))
    with pytest.raises(InputError, match="'distortion' must hold 5"):
        IntrinsicsArtifact.load(p)
    bad = body + "board: {cols: nine, rows: 6, square: 0.025}\n"
    p.write_text("schema: acscal/intrinsics\nschema_version: 1\n" + bad)
    with pytest.raises(InputError, match=r"board\.cols") as exc:
        IntrinsicsArtifact.load(p)
    assert exc.value.path == str(p)


def _joint(scenario: str = "fixed_joint") -> JointArtifact:
    ca, cb = _cov(), _cov()
    section = JointSection.from_estimate(RNG.normal(size=3), ca, RNG.normal(size=3), cb, units="m")
    bundle = BundleSection(
        "cam_a/intrinsics.yaml", 0.05, 0.04, 12,
        np.array([[600.0, 0, 320], [0, 600, 240], [0, 0, 1]]),
        np.array([0.01, 0.0, 0.0, 0.0, 0.0]),
        {"fx": 0.1, "fy": 0.1, "cx": 0.1, "cy": 0.1, "k1": 1e-4, "k2": 1e-4, "p1": 1e-5,
         "p2": 1e-5, "k3": 0.0},
    )  # fmt: skip
    if scenario == "overlap":
        quality = JointQuality(
            frames={"ab": FramesUsed(10, 9, [0.5])},
            residual_rms={"ab": 0.001},
            pairing=Pairing("timestamp", "auto", 10, 1, 0, 0.05),
            estimated_pose_noise={"ab": PoseNoise(0.001, 0.1)},
            bundle_adjustment={"a": bundle, "b": bundle},
        )
    else:
        quality = JointQuality(
            frames={"a": FramesUsed(10, 10, []), "b": FramesUsed(8, 7, [0.3])},
            residual_rms={"a": 0.001, "b": 0.002},
            joint_in_world={"a": RNG.normal(size=3), "b": RNG.normal(size=3)},
            estimated_pose_noise={"a": PoseNoise(0.001, 0.1), "b": PoseNoise(0.002, 0.2)},
            bundle_adjustment={"a": bundle},
        )
    return JointArtifact(scenario, section, quality, ["a warning"], _header("joint"))


@pytest.mark.parametrize("scenario", ["fixed_joint", "overlap"])
def test_joint_round_trip(tmp_path: Path, scenario: str) -> None:
    art = _joint(scenario)
    loaded, doc = _round_trip(art, tmp_path)
    assert isinstance(loaded, JointArtifact)
    assert list(doc)[8:] == ["scenario", "joint", "quality", "warnings"]
    assert list(doc["joint"]) == [
        "position_in_a", "position_in_a_std", "position_in_b", "position_in_b_std",
        "covariance_a", "covariance_b", "units",
    ]  # fmt: skip
    np.testing.assert_allclose(loaded.joint.position_in_a, art.joint.position_in_a, atol=1e-15)
    np.testing.assert_allclose(loaded.joint.covariance("b"), art.joint.covariance_b, atol=1e-15)
    assert loaded.quality.frames == art.quality.frames
    assert loaded.quality.pairing == art.quality.pairing
    assert loaded.quality.residual_rms == art.quality.residual_rms
    assert loaded.quality.estimated_pose_noise == art.quality.estimated_pose_noise
    assert set(loaded.quality.bundle_adjustment) == set(art.quality.bundle_adjustment)
    if scenario == "overlap":
        assert list(doc["quality"]) == [
            "bundle_adjustment", "pairing", "frames", "residual_rms", "estimated_pose_noise",
        ]  # fmt: skip
    else:
        assert list(doc["quality"]) == [
            "bundle_adjustment", "frames", "joint_in_world", "residual_rms",
            "estimated_pose_noise",
        ]  # fmt: skip
    assert "joint in A" in loaded.summary()
    assert load_joint_section(tmp_path / "first.yaml").position_in_b is not None


def test_joint_validation_names_file_and_key(tmp_path: Path) -> None:
    art = _joint()
    p = tmp_path / "joint.yaml"
    art.save(p)
    doc = yaml.safe_load(p.read_text())
    doc["joint"]["covariance_a"] = [[1, 2, 0], [0, 1, 0], [0, 0, 1]]
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=r"joint\.covariance_a.*symmetric") as exc:
        JointArtifact.load(p)
    assert exc.value.path == str(p)
    doc["joint"]["covariance_a"] = [[1, 0, 0], [0, -1, 0], [0, 0, 1]]
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match="positive semi-definite"):
        JointArtifact.load(p)
    doc["joint"]["covariance_a"] = None
    doc["joint"]["position_in_b"] = [1, 2]
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=r"joint\.position_in_b' must be three finite numbers"):
        JointArtifact.load(p)


def _relpose(unknown_scale: bool) -> RelposeArtifact:
    T = _poses(1)[0]
    rel = RelativePose(
        T_b_a=T,
        T_b_a_covariance=np.eye(6) * 1e-6,
        rpy_deg=np.array([1.0, 2.0, 3.0]),
        rpy_deg_std=np.array([0.1, 0.1, 0.1]),
        translation_b_in_a=np.array([0.1, 0.2, 0.3]),
        translation_b_in_a_std=np.array([0.01, 0.01, 0.01]),
        reference=2,
        reference_timestamp_a=0.2,
        reference_timestamp_b=0.2,
        T_wb_wa=_poses(1)[0],
    )
    joint = JointSection.from_estimate(
        RNG.normal(size=3), _cov(), RNG.normal(size=3), _cov(), source="self-calibrated"
    )
    scale = Scale(1.5, 0.01, None, None, None, None) if unknown_scale else None
    quality = RelposeQuality(
        0.002, FramesUsed(10, 9, [0.7]), Pairing("timestamp", "auto", 10, 0, 0, 0.05),
        PoseNoise(0.001, 0.1),
    )  # fmt: skip
    return RelposeArtifact(rel, joint, scale, quality, [], header=_header("relpose"))


@pytest.mark.parametrize("unknown_scale", [False, True])
def test_relpose_round_trip(tmp_path: Path, unknown_scale: bool) -> None:
    art = _relpose(unknown_scale)
    loaded, doc = _round_trip(art, tmp_path)
    assert isinstance(loaded, RelposeArtifact)
    keys = ["scenario", "relative_pose", "joint", *(["scale"] if unknown_scale else [])]
    assert list(doc)[8:] == [*keys, "quality", "warnings"]
    assert list(doc["relative_pose"]) == [
        "T_b_a", "T_b_a_covariance", "rpy_deg", "rpy_deg_std", "translation_b_in_a",
        "translation_b_in_a_std", "reference", "reference_timestamp_a", "reference_timestamp_b",
        "T_wb_wa",
    ]  # fmt: skip
    assert list(doc["quality"]) == ["residual_rms", "frames", "pairing", "estimated_pose_noise"]
    np.testing.assert_allclose(loaded.relative_pose.T_b_a, art.relative_pose.T_b_a, atol=1e-15)
    assert loaded.scale == art.scale and loaded.unknown_scale == unknown_scale
    assert loaded.phi_ba == (1.5 if unknown_scale else 1.0)
    assert loaded.quality.frames.mask(np.array([0.5, 0.7])).tolist() == [False, True]
    assert loaded.require_joint().source == "self-calibrated"
    assert "R_a_b rpy" in loaded.summary()


def test_relpose_validation(tmp_path: Path) -> None:
    p = tmp_path / "relpose.yaml"
    _relpose(True).save(p)
    doc = yaml.safe_load(p.read_text())
    doc["relative_pose"]["T_b_a"][0][0] *= 1.5
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=r"relative_pose\.T_b_a"):
        RelposeArtifact.load(p)
    doc = yaml.safe_load(p.read_text())
    doc["relative_pose"]["T_b_a"][0][0] /= 1.5
    doc["scale"]["phi_ba"] = -2
    p.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError, match=r"scale\.phi_ba' must be a positive number"):
        RelposeArtifact.load(p)
    del doc["joint"]
    doc["scale"]["phi_ba"] = 2
    p.write_text(yaml.safe_dump(doc))
    art = RelposeArtifact.load(p)  # export needs no joint; the trajectory does
    with pytest.raises(InputError, match=r"joint\.position_in_a"):
        art.require_joint()


def _poses_artifact(with_corners: bool = True) -> PosesArtifact:
    n = 6
    traj = Trajectory(
        np.arange(n) * 0.1, _poses(n), "x", "npz", True, tuple(f"img_{i}.png" for i in range(n))
    )
    board = np.zeros((4, 3))
    board[:, 0] = np.arange(4) * 0.025
    return PosesArtifact(
        trajectory=traj,
        reprojection_rms=RNG.uniform(0.1, 0.3, n),
        skipped_images=("img_9.png",),
        corners=RNG.uniform(0, 640, (n, 4, 2)) if with_corners else None,
        board_points=board if with_corners else None,
        header=_header("poses") | {"intrinsics_file": "intrinsics.yaml", "warnings": ["w"]},
    )


@pytest.mark.parametrize("with_corners", [True, False])
def test_poses_round_trip(tmp_path: Path, with_corners: bool) -> None:
    art = _poses_artifact(with_corners)
    p = tmp_path / "poses.npz"
    art.save(p)
    with np.load(p) as z:
        keys = list(z.files)
    assert keys == [
        "schema", "schema_version", "T_world_cam", "timestamps", "has_timestamps",
        "image_names", "time_unit", "header_json", "reprojection_rms", "skipped_images",
        *(["corners", "board_points"] if with_corners else []),
    ]  # fmt: skip
    loaded = PosesArtifact.load(p)
    T0, T1 = art.trajectory.T_world_cam, loaded.trajectory.T_world_cam
    np.testing.assert_allclose(T1, T0, atol=1e-12)
    np.testing.assert_array_equal(loaded.trajectory.timestamps, art.trajectory.timestamps)
    assert loaded.trajectory.names == art.trajectory.names
    np.testing.assert_array_equal(loaded.reprojection_rms, art.reprojection_rms)
    assert loaded.skipped_images == art.skipped_images
    assert loaded.header == art.header and loaded.warnings == ["w"]
    assert loaded.intrinsics_file == "intrinsics.yaml"
    assert loaded.sha256 is not None and len(loaded.sha256) == 64
    if with_corners:
        assert loaded.corners is not None and loaded.front_end == "board"
        np.testing.assert_array_equal(loaded.corners, art.corners)
    else:
        assert loaded.corners is None and loaded.board_points is None
    # the same file through the trajectory reader
    np.testing.assert_allclose(read_trajectory(p, "npz").T_world_cam, loaded.trajectory.T_world_cam)
    assert "6 posed images" in loaded.summary()


def test_poses_plain_npz_and_bad_corners(tmp_path: Path) -> None:
    p = tmp_path / "plain.npz"
    np.savez(p, T_world_cam=_poses(3))
    art = PosesArtifact.load(p)
    assert len(art) == 3 and art.header == {} and art.corners is None
    assert not art.trajectory.has_timestamps
    np.savez(p, T_world_cam=_poses(3), corners=np.zeros((3, 4, 2)), board_points=np.zeros((5, 3)))
    with pytest.raises(InputError, match="do not match"):
        PosesArtifact.load(p)


def test_classes_follow_the_base_pattern() -> None:
    for cls in (IntrinsicsArtifact, JointArtifact, RelposeArtifact, PosesArtifact):
        assert issubclass(cls, Artifact)
        assert cls.KIND in ("intrinsics", "joint", "relpose", "poses")
        for name in ("load", "save", "summary", "validate"):
            assert callable(getattr(cls, name))


def test_validators() -> None:
    assert as_number(2, "k", None) == 2.0
    for bad in (True, "1", None, float("nan"), [1.0]):
        with pytest.raises(InputError, match="'k' must be a finite number"):
            as_number(bad, "k", "f.yaml")
    with pytest.raises(InputError, match="positive"):
        as_number(0.0, "k", None, positive=True)
    assert as_int(3.0, "k", None) == 3
    with pytest.raises(InputError, match="integer"):
        as_int(2**40, "k", None)
    with pytest.raises(InputError, match="at least 0"):
        as_int(-1, "k", None, minimum=0)
    np.testing.assert_array_equal(as_vector([1, 2, 3], "v", None), [1.0, 2.0, 3.0])
    for bad in ([1, 2], [[1, 2, 3]], ["a", "b", "c"], [1, float("inf"), 2], "abc", {"a": 1}):
        with pytest.raises(InputError, match="'v' must be three finite numbers"):
            as_vector(bad, "v", None)
    as_covariance3(np.eye(3), "c", None)
    as_covariance3(np.zeros((3, 3)), "c", None)
    with pytest.raises(InputError, match="symmetric"):
        as_covariance3([[1, 1, 0], [0, 1, 0], [0, 0, 1]], "c", None)
    mask = listed_mask(np.array([0.0, 0.1, 0.2]), [0.1, "x", True, 0.2000000001])
    assert mask.tolist() == [False, True, True]
    assert listed_mask(np.array([0.0]), "not a list").tolist() == [False]
