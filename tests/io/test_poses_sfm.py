"""The poses NPZ of structure from motion (``acscal poses --sfm``): the ``sfm_*`` arrays and
``metric_scale`` round trip through PosesArtifact, are validated on load, and trajectory
readers read the file as any poses NPZ."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from acs_cli.core import se3
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header
from acs_cli.io.poses import SFM_KEYS, PosesArtifact, SfmSummary
from acs_cli.io.trajectory import Trajectory, read_trajectory

RNG = np.random.default_rng(11)
IMAGES = tuple(f"frame_{i}.png" for i in range(7))
REGISTERED = np.array([True, True, False, True, True, False, True])


def _summary(**changes: Any) -> SfmSummary:
    base = SfmSummary(
        images=IMAGES,
        registered=REGISTERED.copy(),
        dropped_images=("frame_5.png",),
        num_models=2,
        num_points3d=1234,
        mean_track_length=5.25,
        reprojection_rms=0.42,
        camera_matrix=np.array([[300.0, 0.0, 159.5], [0.0, 301.0, 119.5], [0.0, 0.0, 1.0]]),
        distortion=np.array([-0.05, 0.0, 0.0, 0.0, 0.0]),
        intrinsics_model="pinhole",
        intrinsics_source="self-calibrated",
        intrinsics_refined=True,
        image_size=(320, 240),
    )
    return replace(base, **changes)


def _artifact(**changes: Any) -> PosesArtifact:
    names = tuple(n for n, r in zip(IMAGES, REGISTERED, strict=True) if r)
    n = len(names)
    R = Rotation.random(n, random_state=RNG).as_matrix()
    T = se3.transforms_from_rt(R, RNG.uniform(-1, 1, (n, 3))).reshape(n, 4, 4)
    t = np.array([float(x.split("_")[1].split(".")[0]) for x in names])
    header = make_header("poses", {}, method="test", units={"length": "SfM units"}, frames={}) | {
        "front_end": "sfm",
        "sfm": {"matching": "exhaustive"},
        "warnings": ["w"],
    }
    art = PosesArtifact(
        trajectory=Trajectory(t, T, "x", "npz", True, names),
        reprojection_rms=RNG.uniform(0.2, 0.6, n),
        skipped_images=("frame_2.png", "frame_5.png"),
        metric_scale=False,
        sfm=_summary(),
        header=header,
    )
    return replace(art, **changes)


def test_sfm_poses_round_trip(tmp_path: Path) -> None:
    art = _artifact()
    p = tmp_path / "poses.npz"
    art.save(p)
    with np.load(p) as z:
        keys = set(z.files)
        assert z["sfm_registered"].dtype == bool and z["sfm_num_points3d"].dtype == np.int64
        assert str(z["sfm_intrinsics_source"]) == "self-calibrated"
    assert {"metric_scale", *SFM_KEYS} <= keys
    assert not {"corners", "board_points"} & keys
    got = PosesArtifact.load(p)
    assert got.front_end == "sfm" and got.metric_scale is False and got.corners is None
    s, s0 = got.sfm, art.sfm
    assert s is not None and s0 is not None
    assert s.images == s0.images and s.dropped_images == s0.dropped_images
    np.testing.assert_array_equal(s.registered, s0.registered)
    assert (s.num_models, s.num_points3d) == (2, 1234)
    assert (s.mean_track_length, s.reprojection_rms) == (5.25, 0.42)
    np.testing.assert_array_equal(s.camera_matrix, s0.camera_matrix)
    np.testing.assert_array_equal(s.distortion, s0.distortion)
    assert (s.intrinsics_model, s.intrinsics_source, s.intrinsics_refined) == (
        "pinhole",
        "self-calibrated",
        True,
    )
    assert s.image_size == (320, 240)
    assert s.registered_names == got.trajectory.names
    assert s.registered_fraction == pytest.approx(5 / 7)
    np.testing.assert_allclose(got.trajectory.T_world_cam, art.trajectory.T_world_cam, atol=1e-12)
    np.testing.assert_array_equal(got.reprojection_rms, art.reprojection_rms)
    assert got.skipped_images == art.skipped_images
    assert got.header["sfm"] == {"matching": "exhaustive"} and got.warnings == ["w"]
    text = got.summary()
    assert "5 of 7 images registered" in text and "scale is unknown" in text
    assert "split into 2 models" in text
    # what relpose, trajectory and the rig read: the trajectory, as from any poses NPZ
    traj = read_trajectory(p)
    assert traj.names == got.trajectory.names and traj.has_timestamps
    np.testing.assert_array_equal(traj.timestamps, [0.0, 1.0, 3.0, 4.0, 6.0])


def test_board_poses_have_no_sfm_section(tmp_path: Path) -> None:
    art = _artifact(sfm=None, metric_scale=None)
    p = tmp_path / "poses.npz"
    art.save(p)
    with np.load(p) as z:
        assert not any(k.startswith("sfm_") or k == "metric_scale" for k in z.files)
    got = PosesArtifact.load(p)
    assert got.sfm is None and got.metric_scale is None and got.front_end == "trajectory"


def _rewrite(src: Path, dst: Path, **changes: Any) -> Path:
    """A copy of an NPZ with arrays replaced (``None`` removes one)."""
    with np.load(src) as z:
        arrays = {k: z[k] for k in z.files}
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = np.asarray(v)
    with open(dst, "wb") as fh:
        np.savez(fh, **arrays)
    return dst


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"sfm_num_points3d": None}, "not sfm_num_points3d"),
        ({"sfm_registered": REGISTERED.astype(int)}, "'sfm_registered' must be booleans"),
        (
            {"sfm_registered": np.ones(7, bool), "sfm_dropped_images": np.zeros(0, "<U1")},
            "marks 7 images registered but there are 5",
        ),
        ({"sfm_registered": np.ones(6, bool)}, "must be 7 booleans"),
        ({"sfm_dropped_images": np.array(["frame_1.png"])}, "not an unregistered image"),
        ({"sfm_distortion": np.zeros(4)}, "5 finite numbers for the pinhole"),
        ({"sfm_camera_matrix": -np.eye(3)}, "positive fx, fy"),
        ({"sfm_intrinsics_model": np.array("omnidir")}, "'sfm_intrinsics_model' must be one"),
        ({"sfm_intrinsics_source": np.array("guessed")}, "'sfm_intrinsics_source' must be one"),
        ({"sfm_mean_track_length": np.array(np.nan)}, "'sfm_mean_track_length' must be a finite"),
        ({"sfm_num_models": np.array(1.5)}, "'sfm_num_models' must be an integer"),
        ({"sfm_image_size": np.array([320])}, "'sfm_image_size' must be"),
        ({"sfm_images": np.array((*IMAGES[:6], "frame_0.png"))}, "names an image twice"),
        ({"metric_scale": np.array("no")}, "'metric_scale' must be a boolean"),
        (
            {"image_names": np.array(["frame_0.png", "frame_1.png", "frame_3.png", "x", "y"])},
            "are not the images 'sfm_registered' marks",
        ),
    ],
)
def test_bad_sfm_arrays_are_refused(tmp_path: Path, changes: dict[str, Any], message: str) -> None:
    good = tmp_path / "good.npz"
    _artifact().save(good)
    bad = _rewrite(good, tmp_path / "bad.npz", **changes)
    with pytest.raises(InputError, match=message) as info:
        PosesArtifact.load(bad)
    assert str(bad) in str(info.value)


def test_an_inconsistent_artifact_is_not_written(tmp_path: Path) -> None:
    art = _artifact(sfm=_summary(registered=np.ones(7, bool), dropped_images=()))
    with pytest.raises(InputError, match="marks 7 images registered"):
        art.save(tmp_path / "poses.npz")
    assert not (tmp_path / "poses.npz").exists()
