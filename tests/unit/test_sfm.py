"""Structure from motion (acs_cli.core.sfm): intrinsics mapping to COLMAP, trajectories
recovered up to a similarity from a rendered textured sequence, loop closure, split
reconstructions, and sequences it cannot reconstruct."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from acs_cli.core.sfm import (
    SfmCamera,
    SfmOptions,
    SfmResult,
    _rotation_only_residual,
    _sequential_window,
    camera_from_colmap,
    colmap_camera,
    run_sfm,
)
from acs_cli.errors import DegenerateMotionError, InputError
from acs_cli.io.images import list_images
from acs_cli.stages.poses import _sfm_warnings

pycolmap = pytest.importorskip("pycolmap")

W, H = 320, 240
#: Fewer features than COLMAP's default 8192 (these images have ~1500): a faster test.
FAST = SfmOptions(max_features=600)
K_TRUE = np.array([[260.0, 0.0, (W - 1) / 2], [0.0, 260.0, (H - 1) / 2], [0.0, 0.0, 1.0]])


# --------------------------------------------------------------------------------------
# a small textured scene: a far wall and a nearer tilted panel, the camera translating


def _texture(rng: np.random.Generator, size: int) -> np.ndarray:
    """Multi-scale noise (cloud-like, with fine detail), 8-bit."""
    t = np.zeros((size, size))
    for s in (2, 4, 8, 16, 32, 64):
        n = rng.standard_normal((size // s + 2, size // s + 2))
        t += cv2.resize(n, (size + 2 * s, size + 2 * s), interpolation=cv2.INTER_CUBIC)[
            :size, :size
        ] * np.sqrt(s)
    t = (t - t.min()) / (t.max() - t.min())
    return (t * 255).astype(np.uint8)


def _rot(yaw: float, pitch: float, roll: float) -> np.ndarray:
    cy, sy, cp, sp, cr, sr = (f(a) for a in (yaw, pitch, roll) for f in (np.cos, np.sin))
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
    Rz = np.array([[cr, -sr, 0], [sr, cr, 0], [0, 0, 1]])
    return Ry @ Rx @ Rz


def render_sequence(
    folder: Path,
    n: int,
    seed: int = 0,
    *,
    start: int = 0,
    blank: bool = False,
    translate: bool = True,
    panel: bool = True,
) -> np.ndarray:
    """Render ``n`` frames ``frame_<start + i>.png`` (no zero padding); return the true
    ``T_world_cam`` (n, 4, 4).

    The camera moves 2 m sideways (and 0.3 m forwards) with small rotations, in front of
    a textured wall 8 m away and a panel 4 m away (depth for a well-posed SfM);
    ``translate=False`` keeps it in place, panning 0.3 rad (rotations only),
    ``panel=False`` leaves the wall alone, ``blank=True`` renders grey frames.
    """
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    planes = [  # origin, u axis, v axis, size u, size v (m), texture
        (np.array([-6.0, -4.5, 8.0]), np.eye(3)[0], np.eye(3)[1], 12.0, 9.0, _texture(rng, 1024)),
        (
            np.array([-1.0, -1.0, 4.0]),
            np.array([np.cos(0.3), 0.0, np.sin(0.3)]),
            np.eye(3)[1],
            2.5,
            2.0,
            _texture(rng, 512),
        ),
    ]
    xs, ys = np.meshgrid(np.arange(W), np.arange(H))
    rays = np.linalg.inv(K_TRUE) @ np.stack([xs.ravel(), ys.ravel(), np.ones(W * H)])
    poses = []
    for i in range(n):
        s = i / max(1, n - 1)
        c = np.array([-1.0 + 2.0 * s, 0.2 * np.sin(2 * np.pi * s), 0.3 * s])
        R = _rot(0.12 * np.sin(2 * np.pi * s), 0.06 * np.cos(2 * np.pi * s), 0.05 * s)
        if not translate:  # panning in place
            c, R = np.zeros(3), _rot(0.3 * s - 0.15, 0.05 * np.sin(i), 0.0)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, c
        poses.append(T)
        img = np.zeros((H, W), np.uint8)
        depth = np.full((H, W), np.inf)
        for o, u, v, su, sv, tex in planes[: 2 if panel else 1]:
            ts = tex.shape[0]
            A = np.column_stack([u * su / ts, v * sv / ts, o - c])  # texel (a, b, 1) -> world
            Hm = K_TRUE @ R.T @ A
            warped = cv2.warpPerspective(tex, Hm, (W, H), flags=cv2.INTER_LINEAR)
            inside = cv2.warpPerspective(np.ones_like(tex), Hm, (W, H), flags=cv2.INTER_NEAREST)
            normal = np.cross(u, v)
            with np.errstate(divide="ignore"):
                z = ((normal @ (o - c)) / ((R.T @ normal) @ rays)).reshape(H, W)
            sel = (inside > 0) & (z > 0) & (z < depth)
            img[sel], depth[sel] = warped[sel], z[sel]
        if blank:
            img[:] = 128
        noisy = img + rng.normal(0.0, 2.0, img.shape)
        cv2.imwrite(str(folder / f"frame_{start + i}.png"), np.clip(noisy, 0, 255).astype(np.uint8))
    return np.stack(poses)


def _names(folder: Path) -> list[str]:
    return [p.name for p in list_images(folder)]


def _umeyama(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``R, t, s`` minimising ``sum |Q_i - (s R P_i + t)|^2``."""
    mp, mq = P.mean(0), Q.mean(0)
    Pc, Qc = P - mp, Q - mq
    U, S, Vt = np.linalg.svd(Qc.T @ Pc / len(P))
    D = np.eye(3)
    D[2, 2] = np.sign(np.linalg.det(U @ Vt))
    R = U @ D @ Vt
    s = float(np.trace(np.diag(S) @ D) / ((Pc**2).sum() / len(P)))
    return R, mq - s * R @ mp, s


def _similarity_errors(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """Largest rotation error (deg) and camera-centre error / path extent, after aligning
    the estimate to the truth by a similarity."""
    R, t, s = _umeyama(T_est[:, :3, 3], T_true[:, :3, 3])
    centres = s * T_est[:, :3, 3] @ R.T + t
    extent = float(np.linalg.norm(np.ptp(T_true[:, :3, 3], axis=0)))
    pos = float(np.linalg.norm(centres - T_true[:, :3, 3], axis=1).max()) / extent
    pairs = zip(T_est, T_true, strict=True)
    cos = [(np.trace((R @ a[:3, :3]).T @ b[:3, :3]) - 1) / 2 for a, b in pairs]
    rot = float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max())
    return rot, pos


@pytest.fixture(scope="module")
def sequence(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    folder = tmp_path_factory.mktemp("sfm") / "seq"
    return folder, render_sequence(folder, 12)


@pytest.fixture(scope="module")
def given(sequence: tuple[Path, np.ndarray], tmp_path_factory: pytest.TempPathFactory):
    """SfM of the sequence with the true intrinsics, held fixed (auto: exhaustive)."""
    folder, _ = sequence
    cam = SfmCamera("pinhole", (W, H), K_TRUE, np.zeros(5))
    work = tmp_path_factory.mktemp("work")
    return cam, run_sfm(folder, _names(folder), work, cam, FAST)


# --------------------------------------------------------------------------------------
# intrinsics: acscal (OpenCV) <-> COLMAP


@pytest.mark.parametrize(
    ("model", "dist", "colmap"),
    [
        ("pinhole", [-0.21, 0.05, 0.001, -0.002, 0.0], "OPENCV"),
        ("pinhole", [-0.21, 0.05, 0.001, -0.002, 0.03], "FULL_OPENCV"),
        ("rational", [-0.21, 0.05, 0.001, -0.002, 0.03, 0.1, -0.02, 0.01], "FULL_OPENCV"),
        ("fisheye", [0.05, -0.01, 0.003, -0.001], "OPENCV_FISHEYE"),
    ],
)
def test_colmap_camera_projects_as_opencv_does(model: str, dist: list[float], colmap: str) -> None:
    K = np.array([[410.0, 0.0, 322.3], [0.0, 405.0, 236.8], [0.0, 0.0, 1.0]])
    cam = SfmCamera(model, (640, 480), K, np.array(dist))
    name, params = colmap_camera(cam)
    assert name == colmap
    rng = np.random.default_rng(3)
    X = np.column_stack([rng.uniform(-1.5, 1.5, (50, 2)), rng.uniform(2.0, 5.0, 50)])
    if model == "fisheye":
        uv = cv2.fisheye.projectPoints(X[:, None], np.zeros(3), np.zeros(3), K, np.array(dist))[0]
    else:
        uv = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, np.array(dist))[0]
    c = pycolmap.Camera.create_from_model_name(1, name, 400.0, 640, 480)
    c.params = params
    got = np.asarray(c.img_from_cam(X), dtype=float)
    # COLMAP's pixel centres are at +0.5: the same ray lands half a pixel further
    np.testing.assert_allclose(got, uv.reshape(-1, 2) + 0.5, atol=1e-6)
    back = camera_from_colmap(name, params, (640, 480))
    np.testing.assert_allclose(back.camera_matrix, K, atol=1e-12)
    if colmap != "FULL_OPENCV" or model == "rational":
        assert back.model == model
        np.testing.assert_allclose(back.distortion, dist, atol=1e-12)
    else:  # pinhole with k3: becomes rational with k4..k6 = 0
        assert back.model == "rational"
        np.testing.assert_allclose(back.distortion, [*dist, 0, 0, 0], atol=1e-12)


def test_self_calibration_camera_is_a_pinhole_with_k1() -> None:
    cam = camera_from_colmap("SIMPLE_RADIAL", [300.0, 160.0, 120.0, -0.05], (320, 240))
    assert cam.model == "pinhole"
    np.testing.assert_allclose(cam.camera_matrix, [[300, 0, 159.5], [0, 300, 119.5], [0, 0, 1]])
    np.testing.assert_allclose(cam.distortion, [-0.05, 0, 0, 0, 0])


def test_colmap_camera_refuses_what_colmap_cannot_model() -> None:
    K = K_TRUE.copy()
    K[0, 1] = 2.0
    with pytest.raises(InputError, match="skew"):
        colmap_camera(SfmCamera("pinhole", (W, H), K, np.zeros(5)))
    with pytest.raises(InputError, match="COLMAP equivalent"):
        colmap_camera(SfmCamera("omnidir", (W, H), K_TRUE, np.zeros(5)))
    with pytest.raises(InputError, match="4 finite"):
        colmap_camera(SfmCamera("fisheye", (W, H), K_TRUE, np.zeros(5)))


def test_sequential_window_is_colmaps_quadratic_overlap() -> None:
    near = [d for d in range(1, 2000) if _sequential_window(0, d, 10)]
    assert near == [1, 2, 4, 8, 16, 32, 64, 128, 256, 512]
    assert _sequential_window(7, 5, 2) and not _sequential_window(0, 4, 2)


# --------------------------------------------------------------------------------------
# reconstruction


def test_trajectory_recovered_up_to_a_similarity(
    sequence: tuple[Path, np.ndarray], given: tuple[SfmCamera, SfmResult]
) -> None:
    folder, truth = sequence
    _, res = given
    assert res.registered.mean() >= 0.95
    reg = res.registered
    assert res.T_world_cam.shape == (int(reg.sum()), 4, 4)
    # names in the natural (time) order: frame_2 before frame_10
    assert res.registered_names == tuple(n for n in _names(folder) if n in res.registered_names)
    rot, pos = _similarity_errors(res.T_world_cam, truth[reg])
    assert rot < 1.0
    assert pos < 0.01
    # the gauge: world = first registered camera, mean step between centres = 1
    np.testing.assert_allclose(res.T_world_cam[0], np.eye(4), atol=1e-9)
    steps = np.linalg.norm(np.diff(res.T_world_cam[:, :3, 3], axis=0), axis=1)
    assert steps.mean() == pytest.approx(1.0)
    # quality numbers of the model
    assert res.num_points3d > 500
    assert 2.0 < res.mean_track_length <= len(res.image_names)
    assert 0.0 < res.reprojection_rms < 1.0
    assert res.reprojection_rms_per_image.shape == (int(reg.sum()),)
    assert np.all(res.reprojection_rms_per_image < 1.5)
    assert res.matching == "exhaustive" and res.num_models == 1 and not res.dropped_images
    assert res.parallax_deg > 2.0  # the translation is well determined


def test_given_intrinsics_are_held_fixed(given: tuple[SfmCamera, SfmResult]) -> None:
    cam, res = given
    assert res.intrinsics_source == "given" and not res.intrinsics_refined
    assert res.camera is cam
    name, params = colmap_camera(cam)
    assert res.colmap_model == name
    np.testing.assert_allclose(res.colmap_params, params, rtol=0, atol=1e-12)


def test_refined_intrinsics_that_drift_get_a_warning(given: tuple[SfmCamera, SfmResult]) -> None:
    cam, res = given
    K = cam.camera_matrix.copy()
    K[1, 1] *= 0.9  # fy moved 10%, fx not: the aspect ratio changed
    drifted = replace(res, camera=replace(cam, camera_matrix=K), intrinsics_refined=True)
    assert any("moved far from the given ones" in w for w in _sfm_warnings(drifted, cam))
    K[1, 1] = K[0, 0] * 1.001
    close = replace(res, camera=replace(cam, camera_matrix=K), intrinsics_refined=True)
    assert not any("moved far" in w for w in _sfm_warnings(close, cam))
    assert not any("moved far" in w for w in _sfm_warnings(drifted))  # nothing given


def test_self_calibration_finds_the_focal_length(
    sequence: tuple[Path, np.ndarray], tmp_path: Path
) -> None:
    folder, truth = sequence
    res = run_sfm(folder, _names(folder), tmp_path, None, FAST)
    assert res.intrinsics_source == "self-calibrated" and res.colmap_model == "SIMPLE_RADIAL"
    assert res.camera.camera_matrix[0, 0] == pytest.approx(260.0, rel=0.02)
    rot, _ = _similarity_errors(res.T_world_cam, truth[res.registered])
    assert rot < 1.0
    assert "self-calibrated" in _sfm_warnings(res)[0]


def test_loop_closure_adds_pairs_beyond_the_sequential_window(
    sequence: tuple[Path, np.ndarray], tmp_path: Path
) -> None:
    """Sequential matching pairs images 1, 2, 4 and 8 frames apart; loop closure (a
    vocabulary trained on the sequence, no download) also pairs images that look alike.
    The count of loop pairs is checked against COLMAP's database."""
    folder, truth = sequence
    cam = SfmCamera("pinhole", (W, H), K_TRUE, np.zeros(5))
    opts = replace(FAST, matching="sequential", loop_closure=True)
    res = run_sfm(folder, _names(folder), tmp_path, cam, opts)
    assert res.matching == "sequential" and res.loop_closure.startswith("own vocabulary")
    assert (tmp_path / "vocab_tree.bin").is_file()
    db = pycolmap.Database.open(tmp_path / "database.db")
    try:
        index = {im.image_id: int(Path(im.name).stem) for im in db.read_all_images()}
        pair_ids, geometries = db.read_two_view_geometries()
    finally:
        db.close()
    gaps = []
    for pair, geometry in zip(pair_ids, geometries, strict=True):
        a, b = pycolmap.pair_id_to_image_pair(pair)
        if geometry.inlier_matches.shape[0]:
            gaps.append(abs(index[a] - index[b]))
    assert res.verified_pairs == len(gaps)
    beyond = [g for g in gaps if g not in (1, 2, 4, 8)]
    assert res.loop_pairs == len(beyond) > 0
    rot, _ = _similarity_errors(res.T_world_cam, truth[res.registered])
    assert res.registered.all() and rot < 1.0


def test_a_split_reconstruction_keeps_the_largest_model(tmp_path: Path) -> None:
    """Two unrelated scenes in one folder: two models; the smaller one's images are
    named as dropped."""
    folder = tmp_path / "seq"
    render_sequence(folder, 8, seed=1)
    render_sequence(folder, 5, seed=2, start=8)
    cam = SfmCamera("pinhole", (W, H), K_TRUE, np.zeros(5))
    work = tmp_path / "work"
    work.mkdir()
    res = run_sfm(folder, _names(folder), work, cam, FAST)
    assert res.num_models == 2 and res.model_sizes[0] >= res.model_sizes[1] >= 3
    first = {f"frame_{i}.png" for i in range(8)}
    second = {f"frame_{i}.png" for i in range(8, 13)}
    assert set(res.registered_names) <= first and len(res.registered_names) >= 7
    assert set(res.dropped_images) <= second and len(res.dropped_images) >= 3
    warning = next(w for w in _sfm_warnings(res) if "split into 2 models" in w)
    assert all(name in warning for name in res.dropped_images)


def test_blank_frames_are_degenerate(tmp_path: Path) -> None:
    folder = tmp_path / "blank"
    render_sequence(folder, 5, blank=True)
    work = tmp_path / "work"
    work.mkdir()
    with pytest.raises(DegenerateMotionError, match="textureless") as info:
        run_sfm(folder, _names(folder), work, None, SfmOptions())
    assert "record the sequence again" in info.value.message
    assert info.value.exit_code == 3


def test_a_camera_that_only_rotates_is_degenerate(tmp_path: Path) -> None:
    """Turning in place in front of a wall: COLMAP makes up a translation (a plane seen
    through a narrow lens), but a rotation alone explains the images."""
    folder = tmp_path / "pan"
    render_sequence(folder, 12, translate=False, panel=False)
    work = tmp_path / "work"
    work.mkdir()
    with pytest.raises(DegenerateMotionError, match="only rotated"):
        run_sfm(folder, _names(folder), work, None, FAST)


@pytest.mark.parametrize(("baseline", "low", "high"), [(0.0, 0.0, 0.2), (1.0, 1.0, 10.0)])
def test_rotation_only_residual_measures_parallax(baseline: float, low: float, high: float) -> None:
    """Rays of points 4-8 m away from cameras that turn (and move ``baseline`` m): what no
    rotation explains is the noise (0.05 deg) without translation, the parallax with."""
    rng = np.random.default_rng(4)
    X = np.column_stack([rng.uniform(-3, 3, (300, 2)), rng.uniform(4, 8, 300)])
    pids, rays = [], []
    for k in range(6):
        R = _rot(0.1 * k, 0.03 * k, -0.02 * k)
        c = np.array([baseline * k / 5, 0.0, 0.0])
        ray = (X - c) @ R  # R^T (X - c), row-wise
        ray += rng.normal(0.0, np.radians(0.05), ray.shape) * np.linalg.norm(ray, axis=1)[:, None]
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        keep = rng.permutation(300)[:250]
        pids.append(keep.astype(np.int64))
        rays.append(ray[keep])
    assert low <= _rotation_only_residual(pids, rays) <= high
    assert np.isnan(_rotation_only_residual(pids[:1], rays[:1]))


def test_too_few_images_are_degenerate(sequence: tuple[Path, np.ndarray], tmp_path: Path) -> None:
    folder, _ = sequence
    with pytest.raises(DegenerateMotionError, match="at least 3 images"):
        run_sfm(folder, _names(folder)[:2], tmp_path, None, SfmOptions())


def test_options_are_checked() -> None:
    with pytest.raises(InputError, match="matching"):
        SfmOptions(matching="vocab")
    with pytest.raises(InputError, match="max-image-size"):
        SfmOptions(max_image_size=8)
