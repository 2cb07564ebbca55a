"""``acscal poses --sfm`` end to end: markerless poses of a rendered textured sequence, the
NPZ other commands read, and the folders and options it refuses."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import read_trajectory

pytest.importorskip("pycolmap")

W, H = 320, 240
F = 260.0
#: Fewer SIFT features than the default (these images have ~1500): a faster test.
FAST = ("--max-features", "600")


def _texture(rng: np.random.Generator, size: int) -> np.ndarray:
    t = np.zeros((size, size))
    for s in (2, 4, 8, 16, 32, 64):
        n = rng.standard_normal((size // s + 2, size // s + 2))
        big = cv2.resize(n, (size + 2 * s, size + 2 * s), interpolation=cv2.INTER_CUBIC)
        t += big[:size, :size] * np.sqrt(s)
    return ((t - t.min()) / (t.max() - t.min()) * 255).astype(np.uint8)


def _render(folder: Path, n: int, seed: int = 0) -> np.ndarray:
    """``frame_<i>.png``: a camera moving 2 m sideways in front of a textured wall (8 m)
    and panel (4 m), turning a little about every axis (a turn about one axis only leaves
    fx/fy undetermined); returns the true ``T_world_cam`` (n, 4, 4)."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    K = np.array([[F, 0.0, (W - 1) / 2], [0.0, F, (H - 1) / 2], [0.0, 0.0, 1.0]])
    tilt = np.array([np.cos(0.3), 0.0, np.sin(0.3)])
    planes = [
        (np.array([-6.0, -4.5, 8.0]), np.eye(3)[0], 12.0, 9.0, _texture(rng, 1024)),
        (np.array([-1.0, -1.0, 4.0]), tilt, 2.5, 2.0, _texture(rng, 512)),
    ]
    xs, ys = np.meshgrid(np.arange(W), np.arange(H))
    rays = np.linalg.inv(K) @ np.stack([xs.ravel(), ys.ravel(), np.ones(W * H)])
    poses = []
    for i in range(n):
        s = i / (n - 1)
        c = np.array([-1.0 + 2.0 * s, 0.2 * np.sin(2 * np.pi * s), 0.3 * s])
        R = cv2.Rodrigues(
            np.array([0.06 * np.cos(2 * np.pi * s), 0.12 * np.sin(2 * np.pi * s), 0.05 * s])
        )[0]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, c
        poses.append(T)
        img = np.zeros((H, W), np.uint8)
        depth = np.full((H, W), np.inf)
        for o, u, su, sv, tex in planes:
            v, ts = np.eye(3)[1], tex.shape[0]
            Hm = K @ R.T @ np.column_stack([u * su / ts, v * sv / ts, o - c])
            warped = cv2.warpPerspective(tex, Hm, (W, H))
            inside = cv2.warpPerspective(np.ones_like(tex), Hm, (W, H), flags=cv2.INTER_NEAREST)
            normal = np.cross(u, v)
            with np.errstate(divide="ignore"):
                z = ((normal @ (o - c)) / ((R.T @ normal) @ rays)).reshape(H, W)
            sel = (inside > 0) & (z > 0) & (z < depth)
            img[sel], depth[sel] = warped[sel], z[sel]
        noisy = np.clip(img + rng.normal(0.0, 2.0, img.shape), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"frame_{i}.png"), noisy)
    return np.stack(poses)


def _rotation_errors_deg(T_est: np.ndarray, T_true: np.ndarray) -> np.ndarray:
    """Rotation error of each pose after the best common rotation (SfM's world is free)."""
    M = sum(b[:3, :3] @ a[:3, :3].T for a, b in zip(T_est, T_true, strict=True))
    U, _, Vt = np.linalg.svd(M)
    G = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    pairs = zip(T_est, T_true, strict=True)
    cos = [(np.trace((G @ a[:3, :3]).T @ b[:3, :3]) - 1) / 2 for a, b in pairs]
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    folder = tmp_path_factory.mktemp("sfm") / "cam_a"
    return folder, _render(folder, 12)


def test_sfm_poses_self_calibrated(sequence: tuple[Path, np.ndarray], tmp_path: Path) -> None:
    folder, truth = sequence
    out, tum = tmp_path / "poses.npz", tmp_path / "poses.txt"
    res = acscal("poses", folder, "--sfm", "-o", out, "--tum", tum, *FAST)
    assert res.returncode == 0, res.stderr
    assert "12 of 12 images registered" in res.stdout and "scale unknown" in res.stdout
    for phase in ("reading images", "extracting features", "matching", "registering images"):
        assert f"sfm: {phase}" in res.stderr
    assert "self-calibrated" in res.stderr  # the warning
    art = PosesArtifact.load(out)
    assert art.front_end == "sfm" and art.metric_scale is False
    sfm = art.sfm
    assert sfm is not None and sfm.registered.all() and sfm.num_models == 1
    assert sfm.intrinsics_source == "self-calibrated" and sfm.intrinsics_model == "pinhole"
    assert sfm.camera_matrix[0, 0] == pytest.approx(F, rel=0.02)
    assert sfm.num_points3d > 300 and sfm.mean_track_length > 2 and sfm.reprojection_rms < 1
    assert art.header["units"]["length"].startswith("SfM units")
    assert art.header["sfm"]["matching"] == "exhaustive"  # 12 images: auto
    assert art.header["sfm"]["camera"]["colmap_model"] == "SIMPLE_RADIAL"
    assert any("self-calibrated" in w for w in art.warnings)
    traj = art.trajectory
    assert traj.names == tuple(f"frame_{i}.png" for i in range(12))  # natural order
    assert traj.has_timestamps and list(traj.timestamps) == list(range(12))
    assert _rotation_errors_deg(traj.T_world_cam, truth).max() < 1.0
    # what relpose --unknown-scale reads: the NPZ, and the TUM file
    for path in (out, tum):
        got = read_trajectory(path)
        assert len(got) == 12
        np.testing.assert_allclose(got.T_world_cam, traj.T_world_cam, atol=1e-9)


def test_sfm_poses_with_intrinsics_refined_and_workdir_kept(
    sequence: tuple[Path, np.ndarray], tmp_path: Path
) -> None:
    """A 5%-wrong focal length, refined by SfM; sequential matching; COLMAP's files kept."""
    folder, _ = sequence
    intr = tmp_path / "intrinsics.yaml"
    intr.write_text(
        yaml.safe_dump(
            {
                "schema": "acscal/intrinsics",
                "schema_version": 1,
                "model": "pinhole",
                "image_size": [W, H],
                "camera_matrix": [
                    [1.05 * F, 0, (W - 1) / 2],
                    [0, 1.05 * F, (H - 1) / 2],
                    [0, 0, 1],
                ],
                "distortion": [0.0, 0.0, 0.0, 0.0, 0.0],
            }
        )
    )
    out, work = tmp_path / "poses.npz", tmp_path / "colmap"
    args = ["poses", folder, "--sfm", "--intrinsics", intr, "-o", out, "--workdir", work]
    res = acscal(
        *args, "--refine-intrinsics", "--matching", "sequential", "--no-loop-closure", *FAST
    )
    assert res.returncode == 0, res.stderr
    assert "given, refined" in res.stdout and "self-calibrated" not in res.stderr
    art = PosesArtifact.load(out)
    sfm = art.sfm
    assert sfm is not None and sfm.intrinsics_source == "given" and sfm.intrinsics_refined
    fx, fy = sfm.camera_matrix[0, 0], sfm.camera_matrix[1, 1]
    assert abs(fx - F) < 0.5 * 0.05 * F and abs(fy - F) < 0.5 * 0.05 * F  # towards the truth
    assert "moved far" not in res.stderr
    assert art.header["sfm"]["camera"]["colmap_model"] == "OPENCV"
    assert art.header["sfm"]["matching"] == "sequential"
    assert art.header["sfm"]["loop_closure"] == "off"
    assert art.intrinsics_file == str(intr)
    assert (work / "database.db").is_file() and (work / "sparse" / "0").is_dir()
    assert (work / ".acscal-sfm").is_file()
    # a folder with someone else's files is refused before any work
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    res = acscal("poses", folder, "--sfm", "-o", tmp_path / "x.npz", "--workdir", foreign)
    assert res.returncode == 2 and "--workdir is not empty" in res.stderr
    assert (foreign / "notes.txt").read_text() == "mine" and not (tmp_path / "x.npz").exists()


def test_blank_folder_exits_3_and_writes_nothing(tmp_path: Path) -> None:
    folder = tmp_path / "blank"
    folder.mkdir()
    rng = np.random.default_rng(1)
    for i in range(6):
        img = np.clip(128 + rng.normal(0, 1.0, (H, W)), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"frame_{i}.png"), img)
    out, tum = tmp_path / "out" / "poses.npz", tmp_path / "out" / "poses.txt"
    res = acscal("poses", folder, "--sfm", "-o", out, "--tum", tum)
    assert res.returncode == 3, res.stderr
    assert "textureless" in res.stderr and "record the sequence again" in res.stderr
    assert not out.exists() and not tum.exists()
    assert not list((tmp_path / "out").glob("*"))  # no temporary leftovers either


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--board", "9x6"], "--board describe"),
        (["--square", "0.03"], "--square describe"),
        (["--refine-intrinsics"], "--refine-intrinsics needs --intrinsics"),
        (["--matching", "nearest"], "nearest"),
    ],
)
def test_sfm_refuses_options_that_do_not_apply(
    sequence: tuple[Path, np.ndarray], tmp_path: Path, extra: list[str], message: str
) -> None:
    folder, _ = sequence
    out = tmp_path / "poses.npz"
    res = acscal("poses", folder, "--sfm", "-o", out, *extra)
    assert res.returncode == 2
    assert message in res.stderr
    assert not out.exists()


def test_board_poses_refuse_sfm_options(sequence: tuple[Path, np.ndarray], tmp_path: Path) -> None:
    folder, _ = sequence
    out = tmp_path / "poses.npz"
    res = acscal("poses", folder, "-o", out, "--matching", "sequential")
    assert res.returncode == 2 and "only apply with --sfm" in res.stderr
    res = acscal("poses", folder, "-o", out)
    assert res.returncode == 2 and "board poses need --intrinsics" in res.stderr
    assert not out.exists()


def test_sfm_bad_input_exits_2(sequence: tuple[Path, np.ndarray], tmp_path: Path) -> None:
    folder, _ = sequence
    # a corrupt image, named
    bad = tmp_path / "bad"
    bad.mkdir()
    for i in range(4):
        (bad / f"frame_{i}.png").write_bytes((folder / f"frame_{i}.png").read_bytes())
    data = (bad / "frame_2.png").read_bytes()
    (bad / "frame_2.png").write_bytes(data[: len(data) // 2])
    out = tmp_path / "poses.npz"
    res = acscal("poses", bad, "--sfm", "-o", out)
    assert res.returncode == 2 and "frame_2.png" in res.stderr
    # intrinsics of another image size
    intr = tmp_path / "intrinsics.yaml"
    intr.write_text(
        yaml.safe_dump(
            {
                "camera_matrix": [[500, 0, 319.5], [0, 500, 239.5], [0, 0, 1]],
                "distortion": [0, 0, 0, 0, 0],
                "image_size": [640, 480],
            }
        )
    )
    res = acscal("poses", folder, "--sfm", "--intrinsics", intr, "-o", out)
    assert res.returncode == 2 and "not an acscal artifact" in res.stderr  # no schema
    doc = yaml.safe_load(intr.read_text())
    intr.write_text(yaml.safe_dump({"schema": "acscal/intrinsics", "schema_version": 1, **doc}))
    res = acscal("poses", folder, "--sfm", "--intrinsics", intr, "-o", out)
    assert res.returncode == 2 and "calibrated at 640x480" in res.stderr
    # a skewed camera COLMAP cannot model
    doc = yaml.safe_load(intr.read_text())
    doc["camera_matrix"] = [[260, 3, 159.5], [0, 260, 119.5], [0, 0, 1]]
    doc["image_size"] = [W, H]
    intr.write_text(yaml.safe_dump(doc))
    res = acscal("poses", folder, "--sfm", "--intrinsics", intr, "-o", out)
    assert res.returncode == 2 and "skew" in res.stderr and "intrinsics.yaml" in res.stderr
    assert not out.exists()
