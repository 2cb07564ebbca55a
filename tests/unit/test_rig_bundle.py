"""The rig's bundle adjustment on its cameras' corners (issue 9): a ball, a hinge and a
rigid joint refined together, beyond the pose-based estimate; bad input refused."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from test_bundle import LENSES, hide_corners  # the same lenses and partial views

from acs_cli.core import lsq, se3
from acs_cli.core.camera_models import camera_model
from acs_cli.core.rig_bundle import CameraViews, RigBundle, bundle_adjust_rig
from acs_cli.core.rig_solve import Recordings, RigEstimate, estimate_rig
from acs_cli.errors import DegenerateMotionError, InputError
from sample_data_gen.rig_sim import CornerRecording, rig_corner_recording

JOINTS = (
    ("j01", ("cam0", "cam1"), "ball"),
    ("j12", ("cam1", "cam2"), "hinge"),
    ("r03", ("cam0", "cam3"), "rigid"),
)
NOISE_PX = 0.2


@pytest.fixture(scope="module")
def solved() -> tuple[CornerRecording, RigEstimate, RigBundle, int]:
    rec = rig_corner_recording(np.random.default_rng(7), 120, joints=JOINTS, noise_px=NOISE_PX)
    common = rec.common
    ref = int(np.flatnonzero(common)[0])
    est = estimate_rig(rec.rig.topology, rec.tracks(), reference_frame=ref)
    ba = bundle_adjust_rig(rec.rig.topology, rec.views(), est, np.flatnonzero(common))
    return rec, est, ba, ref


def _pose_errors(truth: np.ndarray, T: np.ndarray) -> tuple[float, float]:
    d = truth[:3, :3].T @ T[:3, :3]
    return float(se3.rotation_angle_deg(d)), float(np.linalg.norm(T[:3, 3] - truth[:3, 3]))


def test_the_bundle_fits_the_corners_to_their_noise(solved: tuple) -> None:
    _rec, _est, ba, _ref = solved
    assert ba.success
    assert ba.sigma_px == pytest.approx(NOISE_PX, rel=0.1)
    for c, rms in ba.rms_px.items():
        assert rms == pytest.approx(np.sqrt(2) * NOISE_PX, rel=0.1), c


def test_every_camera_pose_beats_the_pose_based_estimate_within_its_std(solved: tuple) -> None:
    rec, est, ba, ref = solved
    truth = rec.rig.T_cam_ref(ref)
    for c in rec.rig.topology.cameras:
        if c == rec.rig.topology.reference:
            continue
        rot, trans = _pose_errors(truth[c], ba.estimate.cameras[c].T_cam_ref)
        rot0, trans0 = _pose_errors(truth[c], est.cameras[c].T_cam_ref)
        cam = ba.estimate.cameras[c]
        # within 4 sigma of the reported uncertainty, and far better than from PnP poses
        # solved with intrinsics 0.3% off
        assert rot < 4 * np.linalg.norm(cam.rotation_std_deg), (c, rot, cam.rotation_std_deg)
        assert trans < 4 * np.linalg.norm(cam.translation_std), (c, trans, cam.translation_std)
        assert trans < 0.25 * trans0, (c, trans, trans0)
        assert rot < 0.5 * rot0, (c, rot, rot0)


def test_joints_and_intrinsics_are_recovered(solved: tuple) -> None:
    rec, est, ba, _ref = solved
    for name in ("j01", "j12"):
        truth = rec.rig.edges[name]
        e = ba.estimate.edges[name]
        p, q = e.joint.between
        for c, o in ((p, truth.o_p), (q, truth.o_q)):
            err = np.linalg.norm(e.position_in[c] - o)
            std = np.sqrt(np.trace(e.position_cov_in[c]))
            assert err < 4 * std and err < 0.005, (name, c, err, std)
            assert err < np.linalg.norm(est.edges[name].position_in[c] - o)
    hinge = ba.estimate.edges["j12"]
    axis = rec.rig.edges["j12"].axis_p
    assert axis is not None
    ang = np.degrees(np.arccos(min(abs(float(hinge.axis_in["cam1"] @ axis)), 1.0)))
    assert ang < 4 * hinge.axis_std_deg_in["cam1"] and ang < 0.2
    assert float(hinge.position_in["cam1"] @ hinge.axis_in["cam1"]) == pytest.approx(0, abs=1e-9)
    for c in rec.rig.topology.cameras:
        err = np.abs(ba.intrinsics[c][:4] - rec.intrinsics[c][:4])
        assert np.all(err < 4 * ba.intrinsics_std[c][:4] + 1e-9), (c, err, ba.intrinsics_std[c])
        err0 = np.abs(rec.intrinsics0[c][:4] - rec.intrinsics[c][:4])
        assert err[:2].max() < err0[:2].max()
        assert ba.intrinsics_std[c][8] == 0.0  # k3 held


def test_cameras_in_any_order_with_their_own_corners_and_noise() -> None:
    """A reference that is not the first camera (tree order differs from config order);
    one camera (cam1: second in tree order, third in config order) seeing part of its board
    with three times the noise: each camera's residuals and RMS are its own."""
    rec = rig_corner_recording(np.random.default_rng(9), 120, joints=JOINTS, reference="cam2")
    rng = np.random.default_rng(10)
    corners = dict(rec.corners)
    corners["cam1"] = corners["cam1"] + rng.normal(scale=0.6, size=corners["cam1"].shape)
    valid = dict(rec.valid)
    valid["cam1"] = valid["cam1"].copy()
    valid["cam1"][:, 30:] = False
    common = rec.common
    ref = int(np.flatnonzero(common)[0])
    tracks = rec.tracks()
    topo = rec.rig.topology
    assert [s.target for s in topo.tree_order()] != [c for c in topo.cameras if c != "cam2"]
    est = estimate_rig(topo, tracks, reference_frame=ref)
    views = {
        c: CameraViews(corners[c], valid[c], rec.board_points, rec.intrinsics0[c])
        for c in topo.cameras
    }
    ba = bundle_adjust_rig(topo, views, est, np.flatnonzero(common))
    for c in topo.cameras:
        noisy = np.hypot(NOISE_PX, 0.6) if c == "cam1" else NOISE_PX
        assert ba.rms_px[c] == pytest.approx(np.sqrt(2) * noisy, rel=0.12), (c, ba.rms_px)
    truth = rec.rig.T_cam_ref(ref)
    for c in topo.cameras:
        rot, trans = _pose_errors(truth[c], ba.estimate.cameras[c].T_cam_ref)
        assert rot < 0.3 and trans < 0.006, (c, rot, trans)
    # the trajectories: at the reference instant the bundle's poses, which T_cam_ref relates
    G = {c: ba.estimate.cameras[c].poses_in_reference_world[ref] for c in topo.cameras}
    for c in topo.cameras:
        T = se3.invert_transforms(G[c]) @ G["cam2"]
        np.testing.assert_allclose(T, ba.estimate.cameras[c].T_cam_ref, atol=1e-9)


def test_the_trajectories_are_the_bundles_per_frame_fit(solved: tuple) -> None:
    """Issue 19: every body's trajectory at the instants adjusted is the bundle's own pose
    ``G[i] T_ref_c[i]`` (its corners reproject with the refined intrinsics and board at the
    bundle's RMS), far closer to the truth than the measured poses; the other instants keep
    the measured poses, mapped by the refined board frame."""
    rec, est, ba, ref = solved
    topo = rec.rig.topology
    frames = ba.frames
    np.testing.assert_array_equal(ba.estimate.bundle_frames, frames)
    assert est.bundle_frames.size == 0
    T_true = se3.invert_transforms(rec.rig.T_W_c[topo.reference][ref])

    def written(e: RigEstimate, c: str) -> np.ndarray:
        """The trajectory as the rig writes it: in the reference camera's frame at ref."""
        G_ref = e.cameras[topo.reference].poses_in_reference_world[ref]
        return se3.invert_transforms(G_ref) @ e.cameras[c].poses_in_reference_world

    for c in topo.cameras:
        e, e0 = ba.estimate.cameras[c], est.cameras[c]
        G, W = e.poses_in_reference_world, e.world_to_reference_world
        X = se3.transform_points(W, rec.board_points)
        x_cam = se3.transform_points(se3.invert_transforms(G[frames])[:, None], X)
        r = camera_model("pinhole").project(x_cam, ba.intrinsics[c]) - rec.corners[c][frames]
        assert np.sqrt(np.mean(np.sum(r**2, axis=2))) == pytest.approx(ba.rms_px[c], rel=1e-6)
        truth = T_true @ rec.rig.T_W_c[c][frames]
        rot, trans = [], []
        for T in (written(ba.estimate, c)[frames], written(est, c)[frames]):
            d = se3.rotvec_from_matrix(np.swapaxes(truth[:, :3, :3], 1, 2) @ T[:, :3, :3])
            rot.append(np.sqrt(np.mean(np.sum(d**2, axis=1))))
            trans.append(np.sqrt(np.mean(np.sum((T[:, :3, 3] - truth[:, :3, 3]) ** 2, axis=1))))
        # 0.4 deg / 17 mm per frame from the measured poses, 0.05 deg / 2 mm from the bundle
        # (benchmarks/bench_rig_bundle.py)
        assert trans[0] < 0.004 and trans[0] < 0.25 * trans[1], (c, trans)
        assert rot[0] < 0.5 * rot[1] + 1e-9, (c, rot)
        # instants the bundle did not adjust (the camera sees its board, another does not)
        other = np.flatnonzero(rec.valid[c].all(axis=1) & ~np.isin(np.arange(G.shape[0]), frames))
        assert other.size
        mapped = W @ se3.invert_transforms(e0.world_to_reference_world)
        np.testing.assert_allclose(
            G[other], mapped @ e0.poses_in_reference_world[other], atol=1e-12
        )


def _through_lenses(
    rec: CornerRecording, models: dict[str, str], rng: np.random.Generator
) -> tuple[dict[str, CameraViews], dict[str, np.ndarray]]:
    """The recording seen through other lenses: each corner's ray through the true pinhole
    lens, projected by a lens of ``models[camera]``, 30-70% of the corners hidden (NaN) in
    half the frames; initial intrinsics off as the recording's (0.3% in focal length, 1 px
    in the centre, 5% in the refined distortion). Views and true intrinsics."""
    views, truth = {}, {}
    for c, model in models.items():
        t = rec.intrinsics[c]
        K = np.array([[t[0], 0, t[2]], [0, t[1], t[3]], [0, 0, 1]])
        px = rec.corners[c]
        crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-15)
        xy = cv2.undistortPointsIter(px.reshape(-1, 1, 2), K, t[4:], None, None, crit)
        rays = np.concatenate([xy.reshape(*px.shape), np.ones((*px.shape[:2], 1))], axis=2)
        cam = camera_model(model)
        scale = 0.7 if model == "fisheye" else 1.0
        truth[c] = np.concatenate([t[:4] * [scale, scale, 1, 1], LENSES[model][1]])
        start = truth[c].copy()
        start[:4] += [0.003 * start[0], 0.003 * start[1], 1.0, -1.0]
        start[cam.free()[4:]] *= 0.95
        corners = hide_corners(rng, cam.project(rays, truth[c]))
        views[c] = CameraViews(corners, rec.valid[c], rec.board_points, start, model)
    return views, truth


def test_the_bundles_hinge_carries_its_whole_geometry(solved: tuple) -> None:
    """The bundle's hinge has its geometry and whole covariance (not the pose-based
    solve's): a point moved along its axis (a rig config's ``joints.<name>.point``) is
    propagated from them, as for the pose-based solve."""
    from acs_cli.core.rig import hinge_point_from_nearest

    rec, est, ba, _ref = solved
    e, e0 = ba.estimate.edges["j12"], est.edges["j12"]
    np.testing.assert_allclose(
        e.geometry[:6], np.concatenate([e.position_in["cam1"], e.position_in["cam2"]])
    )
    np.testing.assert_allclose(e.geometry_covariance[:3, :3], e.position_cov_in["cam1"])
    assert abs(float(e.geometry[6:9] @ e.axis_in["cam1"])) == pytest.approx(1.0)
    assert not np.allclose(e.geometry, e0.geometry)
    # 0.3 m along the axis from the point nearest cam1's centre, in cam1's frame
    truth = rec.rig.edges["j12"]
    assert truth.axis_p is not None and truth.axis_q is not None
    x, C = hinge_point_from_nearest(
        e.geometry, e.geometry_covariance, 0, truth.o_p + 0.3 * truth.axis_p
    )
    for c, want in enumerate((truth.o_p + 0.3 * truth.axis_p, truth.o_q + 0.3 * truth.axis_q)):
        err = np.linalg.norm(x[c] - want)
        assert err < 4 * np.sqrt(np.trace(C[3 * c : 3 * c + 3, 3 * c : 3 * c + 3])), (c, err)


def test_fisheye_and_rational_cameras_with_partial_views() -> None:
    """A rig of fisheye and rational cameras, each missing 30-70% of its corners in half
    the frames: the intrinsics and the joints within their reported uncertainty."""
    rec = rig_corner_recording(np.random.default_rng(7), 100, joints=JOINTS, noise_px=NOISE_PX)
    topo = rec.rig.topology
    models = {"cam0": "fisheye", "cam1": "rational", "cam2": "fisheye", "cam3": "rational"}
    views, truth = _through_lenses(rec, models, np.random.default_rng(8))
    assert set(models) == set(topo.cameras)
    ref = int(np.flatnonzero(rec.common)[0])
    est = estimate_rig(topo, rec.tracks(), reference_frame=ref)
    ba = bundle_adjust_rig(topo, views, est, np.flatnonzero(rec.common))
    assert ba.success
    for c, model in models.items():
        cam = camera_model(model)
        assert ba.intrinsics[c].shape == ba.intrinsics_std[c].shape == (cam.size,)
        assert ba.intrinsics_covariance[c].shape == (cam.size, cam.size)
        free = cam.free()
        err = np.abs(ba.intrinsics[c] - truth[c])[free]
        assert np.all(err < 4 * ba.intrinsics_std[c][free]), (c, err, ba.intrinsics_std[c])
        assert np.all(ba.intrinsics_std[c][cam.size - 3 :] == 0.0) == (model == "rational")
        assert err[0] < 0.5 * 0.003 * truth[c][0], (c, err[0])  # better than the start
    for name in ("j01", "j12"):
        edge, e = rec.rig.edges[name], ba.estimate.edges[name]
        p, q = e.joint.between
        for c, o in ((p, edge.o_p), (q, edge.o_q)):
            err = np.linalg.norm(e.position_in[c] - o)
            assert err < 4 * np.sqrt(np.trace(e.position_cov_in[c])) and err < 0.005, (name, c)


def test_bad_views_are_refused(solved: tuple) -> None:
    rec, est, _ba, ref = solved
    views = rec.views()
    frames = np.flatnonzero(rec.common)
    topo = rec.rig.topology
    with pytest.raises(InputError, match="no corners for camera"):
        bundle_adjust_rig(topo, {c: v for c, v in views.items() if c != "cam2"}, est, frames)
    with pytest.raises(InputError, match="reference instant"):
        bundle_adjust_rig(topo, views, est, frames[frames != ref])
    # 3 frames do not locate a ball between cameras that see different boards (3 rows a
    # frame for its centre and the other board's frame: 12 unknowns; see the pair tests)
    with pytest.raises(DegenerateMotionError, match="do not determine the rig"):
        bundle_adjust_rig(topo, views, est, frames[:3])
    bad = dict(views, cam1=dataclasses.replace(views["cam1"], board_points=np.zeros((3, 3))))
    with pytest.raises(InputError, match="board points"):
        bundle_adjust_rig(topo, bad, est, frames)
    blind = dict(views, cam1=dataclasses.replace(views["cam1"], valid=views["cam1"].valid & False))
    with pytest.raises(InputError, match="cam1 sees fewer than 4 corners"):
        bundle_adjust_rig(topo, blind, est, frames)
    scaled = dataclasses.replace(
        est, cameras=dict(est.cameras, cam1=dataclasses.replace(est.cameras["cam1"], scale_std=0.1))
    )
    with pytest.raises(InputError, match="unknown scale"):
        bundle_adjust_rig(topo, views, scaled, frames)


def test_block_jacobian_equals_column_by_column_differences(rng: np.random.Generator) -> None:
    n_shared, block, n_blocks = 3, 2, 5
    A = rng.normal(size=(n_blocks, 4, n_shared))
    B = rng.normal(size=(n_blocks, 4, block))
    row_block = np.repeat(np.arange(n_blocks), 4)

    def fun(x: np.ndarray) -> np.ndarray:
        s, b = x[:n_shared], x[n_shared:].reshape(n_blocks, block)
        return (np.sin(A @ s) + np.einsum("nij,nj->ni", B, b) ** 2).ravel()

    x = rng.normal(size=n_shared + block * n_blocks)
    J = lsq.block_jacobian(fun, x, fun(x), n_shared, block, row_block).toarray()
    dense = np.zeros_like(J)
    for k in range(x.size):
        h = 1e-6
        e = np.zeros_like(x)
        e[k] = h
        dense[:, k] = (fun(x + e) - fun(x - e)) / (2 * h)
    np.testing.assert_allclose(J, dense, atol=1e-6)
    with pytest.raises(ValueError, match="shared unknowns"):
        lsq.block_jacobian(fun, x[:-1], fun(x), n_shared, block, row_block)


def test_propagate_is_exact_for_a_linear_map(rng: np.random.Generator) -> None:
    M = rng.normal(size=(2, 3))
    x = rng.normal(size=5)
    cols = [1, 2, 4]
    C = np.diag([1.0, 4.0, 9.0])
    value, cov = lsq.propagate(lambda v: M @ v[cols], x, cols, C)
    np.testing.assert_allclose(value, M @ x[cols])
    np.testing.assert_allclose(cov, M @ C @ M.T, rtol=1e-6)


def test_two_recordings_of_a_chain_share_its_joints_and_intrinsics() -> None:
    """A chain cam0 -ball- cam1 -hinge- cam2 from two recordings (the hip trial without
    cam2, the knee trial without cam0): one bundle adjustment over both, each recording with
    its own boards and frames, recovers both joints within their stds and far beyond the
    pose-based estimate, and each camera's intrinsics from every recording that saw it."""
    joints = (("hip", ("cam0", "cam1"), "ball"), ("knee", ("cam1", "cam2"), "hinge"))
    n = 160
    rec = rig_corner_recording(np.random.default_rng(2), n, joints=joints, noise_px=NOISE_PX)
    topo = rec.rig.topology
    tracks, views, recs, common, ref = rec.two_trials("cam0", "cam2")
    est = estimate_rig(topo, tracks, reference_frame=ref, recordings=recs)
    ba = bundle_adjust_rig(topo, views, est, np.flatnonzero(common))
    assert ba.success
    assert ba.sigma_px == pytest.approx(NOISE_PX, rel=0.1)
    for name, (p, q), _ in joints:
        truth = rec.rig.edges[name]
        e, e0 = ba.estimate.edges[name], est.edges[name]
        for c, o in ((p, truth.o_p), (q, truth.o_q)):
            err = np.linalg.norm(e.position_in[c] - o)
            std = np.sqrt(np.trace(e.position_cov_in[c]))
            assert err < 4 * std, (name, c, err, std)
            assert err < 0.5 * np.linalg.norm(e0.position_in[c] - o), (name, c)
    for c in topo.cameras:
        err = np.abs(ba.intrinsics[c][:2] - rec.intrinsics[c][:2])
        assert np.all(err < 4 * ba.intrinsics_std[c][:2]), (c, err, ba.intrinsics_std[c])
    # cam2 was not at the reference instant: no pose there, as in the pose-based estimate
    assert ba.estimate.cameras["cam2"].T_cam_ref is None
    # a recording whose bodies the tree joins only through a body it did not see
    knee = [w for w in est.worlds if w.recording == "knee"]
    worlds = [w for w in est.worlds if w.recording != "knee"]
    worlds += [dataclasses.replace(knee[0], cameras=(c,)) for c in ("cam0", "cam2")]
    with pytest.raises(InputError, match=r"recordings\.knee: bodies cam0, cam2 are not joined"):
        bundle_adjust_rig(
            topo, views, dataclasses.replace(est, worlds=worlds), np.flatnonzero(common)
        )


def test_a_recording_without_frames_adjusted_has_no_unknowns() -> None:
    """A recording none of whose frames is adjusted (one that holds a joint still: the rig
    stage leaves its frames out) adds no boards to the bundle: it is the bundle of the other
    recording alone, and the recording's worlds and poses stay the pose-based estimate's
    (its boards used to be unknowns without rows: the bundle was refused as singular)."""
    n = 120
    rec = rig_corner_recording(np.random.default_rng(2), n, joints=(JOINTS[0],), noise_px=NOISE_PX)
    topo, tracks, views = rec.rig.topology, rec.tracks(), rec.views()
    of = np.repeat([0, 1], n // 2)
    frames = np.flatnonzero(rec.common & (of == 0))
    ref = int(frames[0])
    est = estimate_rig(
        topo, tracks, reference_frame=ref, recordings=Recordings(("a", "b"), of, (False, False))
    )
    ba = bundle_adjust_rig(topo, views, est, frames)
    # the same frames as one recording
    first = {c: dataclasses.replace(t, valid=t.valid & (of == 0)) for c, t in tracks.items()}
    alone = bundle_adjust_rig(topo, views, estimate_rig(topo, first, reference_frame=ref), frames)
    assert ba.success and alone.success
    for c in ("cam0", "cam1"):
        got, want = (
            ba.estimate.edges["j01"].position_in[c],
            alone.estimate.edges["j01"].position_in[c],
        )
        std = np.sqrt(np.diag(alone.estimate.edges["j01"].position_cov_in[c]))
        assert np.all(np.abs(got - want) < 1e-3 * std), (c, got - want, std)
    for w0, w in zip(est.worlds, ba.estimate.worlds, strict=True):
        if w.recording == "b":
            np.testing.assert_array_equal(w.T_ref_world, w0.T_ref_world)
    b = np.flatnonzero(of == 1)
    for c in topo.cameras:
        np.testing.assert_array_equal(
            ba.estimate.cameras[c].poses_in_reference_world[b],
            est.cameras[c].poses_in_reference_world[b],
        )


def test_a_default_prior_std_does_not_depend_on_where_another_recording_is_placed() -> None:
    """A joint point given without a covariance has the engine's default std, a share of the
    reference body's travel in the reference recording: moving the knee recording's worlds
    (untied to the reference's: a choice of gauge) 5 m changes nothing (the travel was taken
    over every recording's frames, and the hip's centre moved by 0.4 mm, 7 of its stds)."""
    from acs_cli.core.rig_solve import EdgePrior

    joints = (("hip", ("cam0", "cam1"), "ball"), ("knee", ("cam1", "cam2"), "hinge"))
    n = 160
    rec = rig_corner_recording(np.random.default_rng(2), n, joints=joints, noise_px=NOISE_PX)
    topo = rec.rig.topology
    tracks, views, recs, common, ref = rec.two_trials("cam0", "cam2")
    of = recs.of_frame
    est = estimate_rig(topo, tracks, reference_frame=ref, recordings=recs)
    D = np.eye(4)
    D[0, 3] = 5.0
    knee = (of == 1)[:, None, None]
    moved = dataclasses.replace(
        est,
        cameras={
            c: dataclasses.replace(
                e,
                poses_in_reference_world=np.where(
                    knee, np.matmul(D, e.poses_in_reference_world), e.poses_in_reference_world
                ),
            )
            for c, e in est.cameras.items()
        },
        worlds=[
            dataclasses.replace(w, T_ref_world=D @ w.T_ref_world) if w.recording == "knee" else w
            for w in est.worlds
        ],
    )
    o = rec.rig.edges["hip"].o_p + np.array([0.005, 0.0, 0.0])
    priors = {"hip": EdgePrior(position_in={"cam0": o}, units="metre")}
    frames = np.flatnonzero(common)
    a, b = (
        bundle_adjust_rig(topo, views, e, frames, priors=priors, hold_intrinsics=True)
        for e in (est, moved)
    )
    for name, c in (("hip", "cam0"), ("hip", "cam1"), ("knee", "cam2")):
        got, want = b.estimate.edges[name].position_in[c], a.estimate.edges[name].position_in[c]
        std = np.sqrt(np.diag(a.estimate.edges[name].position_cov_in[c]))
        assert np.all(np.abs(got - want) < 1e-3 * std), (name, c, got - want, std)
