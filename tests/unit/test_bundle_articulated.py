"""The two-camera bundle adjustment with the joint constraint (overlap and general scenarios):
the two-body rig through the rig's bundle adjustment (:func:`bundle_adjust_rig`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest
from test_bundle import LENSES, hide_corners  # the same lenses and partial views

from acs_cli.core import se3
from acs_cli.core.bundle import intrinsics_vector
from acs_cli.core.camera_models import camera_model
from acs_cli.core.overlap import OVERLAP_RIG, estimate_overlap_rig, joint_of_rig
from acs_cli.core.relpose import (
    TWO_BODY_JOINT,
    JointPrior,
    estimate_relpose,
    prior_for_rig,
    relpose_refined_by,
    two_body_rig,
)
from acs_cli.core.rig_bundle import CameraViews, bundle_adjust_rig
from acs_cli.core.rig_solve import CameraTrack
from acs_cli.errors import DegenerateMotionError, InputError

W, H = 1024, 768
BOARD = np.array([[c * 0.04, r * 0.04, 0.0] for r in range(6) for c in range(9)])
CENTRE = BOARD.mean(axis=0)


def _look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``T_world_cam`` of a camera at ``eye`` looking at ``target`` (z forward, y down)."""
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(-up, z)
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z], axis=1)
    T[:3, 3] = eye
    return T


def _intrinsics(rng: np.random.Generator, model: str = "pinhole") -> np.ndarray:
    f0 = 900.0 if model == "pinhole" else LENSES[model][0]
    K = np.array([[f0 * rng.uniform(0.95, 1.05), 0, 512 + rng.normal(0, 5)],
                  [0, f0 * rng.uniform(0.95, 1.05), 384 + rng.normal(0, 5)],
                  [0, 0, 1]])  # fmt: skip
    d = [rng.uniform(-0.25, 0.05), rng.uniform(-0.05, 0.1), *rng.normal(0, 1e-3, 2), 0.0]
    return intrinsics_vector(K, np.array(d) if model == "pinhole" else LENSES[model][1], model)


def _in_view(uv: np.ndarray) -> bool:
    return bool(np.all(uv > 5) and np.all(uv[:, 0] < W - 5) and np.all(uv[:, 1] < H - 5))


def _scene(
    rng: np.random.Generator,
    overlap: bool,
    sigma_px: float,
    n: int = 20,
    models: tuple[str, str] = ("pinhole", "pinhole"),
    joint: str = "ball",
) -> dict:
    """Camera A looks at board A 0.75 m away; B hangs on a joint beside A and looks at the
    same board (overlap) or at its own board behind A (general). ``joint``: ``hinge`` turns
    B about one axis (its point the axis point nearest A's centre), ``rigid`` not at all."""
    ia, ib = _intrinsics(rng, models[0]), _intrinsics(rng, models[1])
    up = np.array([0.0, -1.0, 0.0])
    T_wa_a_rest = _look_at(CENTRE + np.array([-0.15, 0, -0.75]), CENTRE, up)
    if overlap:
        T_wa_b_rest = _look_at(CENTRE + np.array([0.15, 0, -0.75]), CENTRE, up)
        T_wa_boardb = np.eye(4)
    else:
        T_wa_b_rest = _look_at(
            CENTRE + np.array([0.15, 0, -0.75]), CENTRE + np.array([0.15, 0, -1.5]), up
        )
        T_wa_boardb = _look_at(
            CENTRE + np.array([0.35, 0.1, -1.5]), CENTRE + np.array([0.35, 0.1, -3]), up
        )
        T_wa_boardb[:3, 3] -= T_wa_boardb[:3, :3] @ CENTRE  # board B's centre there
    joint_w = CENTRE + np.array([0.0, -0.12, -0.78])
    o_a = (np.linalg.inv(T_wa_a_rest) @ [*joint_w, 1])[:3]
    o_b = (np.linalg.inv(T_wa_b_rest) @ [*joint_w, 1])[:3]
    T_a_b_rest = np.linalg.inv(T_wa_a_rest) @ T_wa_b_rest
    axis_b = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    axis_a = T_a_b_rest[:3, :3] @ axis_b
    if joint == "hinge":  # the axis point nearest A's centre, the same point in B
        o_a = o_a - (o_a @ axis_a) * axis_a
        o_b = (np.linalg.inv(T_a_b_rest) @ [*o_a, 1])[:3]
    T_wb_wa = np.linalg.inv(T_wa_boardb)
    Ta, Tb, ca, cb, Tab = [], [], [], [], []
    while len(Ta) < n:
        d = np.eye(4)
        d[:3, :3] = se3.matrix_from_rotvec(rng.normal(0, 0.08, 3))
        d[:3, 3] = rng.normal(0, 0.05, 3)
        T_wa_a = T_wa_a_rest @ d
        if joint == "ball":
            R_ab = T_a_b_rest[:3, :3] @ se3.matrix_from_rotvec(rng.normal(0, 0.12, 3))
        elif joint == "hinge":
            R_ab = T_a_b_rest[:3, :3] @ se3.matrix_from_rotvec(rng.normal(0, 0.2) * axis_b)
        else:
            R_ab = T_a_b_rest[:3, :3]
        T_a_b = np.eye(4)
        T_a_b[:3, :3], T_a_b[:3, 3] = R_ab, o_a - R_ab @ o_b
        T_wb_b = T_wb_wa @ T_wa_a @ T_a_b
        ua = camera_model(models[0]).project(
            BOARD @ np.linalg.inv(T_wa_a)[:3, :3].T + np.linalg.inv(T_wa_a)[:3, 3], ia
        )
        Tbw = np.linalg.inv(T_wb_b)
        ub = camera_model(models[1]).project(BOARD @ Tbw[:3, :3].T + Tbw[:3, 3], ib)
        if not (_in_view(ua) and _in_view(ub)):
            continue
        Ta.append(T_wa_a)
        Tb.append(T_wb_b)
        Tab.append(T_a_b)
        ca.append(ua + rng.normal(0, sigma_px, ua.shape))
        cb.append(ub + rng.normal(0, sigma_px, ub.shape))
    return {
        "ia": ia, "ib": ib, "o_a": o_a, "o_b": o_b, "T_wa_a": np.array(Ta),
        "T_wb_b": np.array(Tb), "T_b_a": np.linalg.inv(np.array(Tab)), "T_wb_wa": T_wb_wa,
        "ca": np.array(ca), "cb": np.array(cb), "axis_a": axis_a, "axis_b": axis_b,
    }  # fmt: skip


def _perturb(T: np.ndarray, rng: np.random.Generator, rot: float, trans: float) -> np.ndarray:
    d = se3.transforms_from_rt(
        se3.matrix_from_rotvec(rng.normal(0, rot, (len(T), 3))), rng.normal(0, trans, (len(T), 3))
    )
    return np.matmul(T, d)


@dataclass
class _PairBundle:
    """The two-body rig's bundle adjustment in the two-camera vocabulary (reference: the
    first frame)."""

    success: bool
    rms_px: dict[str, float]
    models: tuple[str, str]
    intrinsics_a: np.ndarray
    intrinsics_b: np.ndarray
    intrinsics_covariance_a: np.ndarray
    intrinsics_std_b: np.ndarray
    position_in_a: np.ndarray
    position_in_b: np.ndarray
    covariance_a: np.ndarray
    T_b_a: np.ndarray  # (4, 4) at the first frame
    pose_covariance: np.ndarray  # (6, 6) of T_b_a
    T_wb_wa: np.ndarray


def _rig_run(
    s: dict,
    rng: np.random.Generator,
    overlap: bool,
    prior: JointPrior | None = None,
    models: tuple[str, str] = ("pinhole", "pinhole"),
) -> _PairBundle:
    """The pose-based two-body rig from perturbed poses (as PnP gives them) and joint, then
    its bundle adjustment (:func:`bundle_adjust_rig`) from perturbed intrinsics, with the
    joint ``prior`` fused (general scenario)."""
    n = s["ca"].shape[0]
    Ta = _perturb(s["T_wa_a"], rng, 0.01, 0.005)
    Tb = _perturb(s["T_wb_b"], rng, 0.01, 0.005)
    ia0, ib0 = s["ia"].copy(), s["ib"].copy()
    ia0[:5] = ia0[:5] * [1.01, 0.99, 1.0, 1.0, 1.0] + [0, 0, 3, -2, 0.01]
    ib0[:2] *= [0.99, 1.01]
    ib0[5] *= 0.99  # k2 (fisheye: k2 too)
    views = {
        c: CameraViews(s[f"c{c}"], np.isfinite(s[f"c{c}"]).all(axis=2), BOARD, i0, m)
        for c, i0, m in (("a", ia0, models[0]), ("b", ib0, models[1]))
    }
    if overlap:
        est = estimate_overlap_rig(Ta, Tb)
        ba = bundle_adjust_rig(OVERLAP_RIG, views, est, np.arange(n))
        j = joint_of_rig(ba.estimate, n)
        # the overlap's reference instant is the frame Algorithm I fits best: T_b_a there
        k = ba.estimate.reference_frame
        cam_b = ba.estimate.cameras["b"]
        T_b_a, C = cam_b.T_cam_ref, cam_b.covariance
        s["k"] = k
        o_a, o_b, C_a = j.position_in_a, j.position_in_b, j.covariance_a
        T_wb_wa = np.eye(4)
    else:
        start = JointPrior(
            s["o_a"] + rng.normal(0, 0.01, 3), s["o_b"] + rng.normal(0, 0.01, 3),
            np.eye(3) * 0.01, np.eye(3) * 0.01,
        )  # fmt: skip
        rel = estimate_relpose(Ta, Tb, start)
        assert rel.rig is not None
        priors = None if prior is None else {TWO_BODY_JOINT: prior_for_rig(prior, False)}
        ba = bundle_adjust_rig(two_body_rig(), views, rel.rig, np.arange(n), priors=priors)
        r = relpose_refined_by(rel, ba.estimate)
        T_b_a, C = r.T_b_a, r.covariance
        o_a, o_b, C_a, T_wb_wa = r.position_in_a, r.position_in_b, r.covariance_a, r.T_wb_wa
        s["k"] = 0
    assert T_b_a is not None
    return _PairBundle(
        ba.success, ba.rms_px, models, ba.intrinsics["a"], ba.intrinsics["b"],
        ba.intrinsics_covariance["a"], ba.intrinsics_std["b"], o_a, o_b, C_a, T_b_a, C,
        T_wb_wa,
    )  # fmt: skip


def _assert_exact(ba: _PairBundle, s: dict[str, Any]) -> None:
    """Noise-free corners: the truth to rounding."""
    assert ba.rms_px["a"] < 1e-6 and ba.rms_px["b"] < 1e-6
    np.testing.assert_allclose(ba.intrinsics_a, s["ia"], rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(ba.intrinsics_b, s["ib"], rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(ba.position_in_a, s["o_a"], atol=1e-8)
    np.testing.assert_allclose(ba.position_in_b, s["o_b"], atol=1e-8)
    np.testing.assert_allclose(ba.T_b_a, s["T_b_a"][s["k"]], atol=1e-8)


@pytest.mark.parametrize("overlap", [True, False], ids=["overlap", "general"])
def test_exact_recovery(rng: np.random.Generator, overlap: bool) -> None:
    s = _scene(rng, overlap, sigma_px=0.0)
    ba = _rig_run(s, rng, overlap)
    assert ba.success
    _assert_exact(ba, s)
    np.testing.assert_allclose(ba.T_wb_wa, s["T_wb_wa"], atol=1e-8)


@pytest.mark.parametrize("joint", ["hinge", "rigid"])
def test_a_hinge_or_a_rigid_pair_recovered_exactly(rng: np.random.Generator, joint: str) -> None:
    """``relpose --joint-type``'s bundle: the two-body rig of a hinge or a rigid mount (its
    own topology) refined on noise-free corners gives the truth: ``T_b_a``, the hinge's
    point and axis in each camera, the intrinsics (general scenario)."""
    s = _scene(rng, False, sigma_px=0.0, joint=joint)
    n = s["ca"].shape[0]
    Ta = _perturb(s["T_wa_a"], rng, 0.01, 0.005)
    Tb = _perturb(s["T_wb_b"], rng, 0.01, 0.005)
    start = None
    if joint == "hinge":
        start = JointPrior(s["o_a"], s["o_b"], np.eye(3) * 1e-4, np.eye(3) * 1e-4)
    rel = estimate_relpose(Ta, Tb, start, joint_type=joint, accept_weak=True)
    assert rel.rig is not None and rel.rig.topology.joints[0].type == joint
    off = {c: np.r_[1.01, 0.99, np.ones(s[f"i{c}"].size - 2)] for c in ("a", "b")}
    views = {
        c: CameraViews(s[f"c{c}"], np.isfinite(s[f"c{c}"]).all(axis=2), BOARD, s[f"i{c}"] * off[c])
        for c in ("a", "b")
    }
    ba = bundle_adjust_rig(rel.rig.topology, views, rel.rig, np.arange(n))
    assert ba.success and ba.rms_px["a"] < 1e-6 and ba.rms_px["b"] < 1e-6
    for c in ("a", "b"):
        np.testing.assert_allclose(ba.intrinsics[c], s[f"i{c}"], rtol=1e-6, atol=1e-8)
    r = relpose_refined_by(rel, ba.estimate)
    np.testing.assert_allclose(r.T_b_a, s["T_b_a"][0], atol=1e-7)
    np.testing.assert_allclose(r.T_wb_wa, s["T_wb_wa"], atol=1e-7)
    if joint == "hinge":
        np.testing.assert_allclose(r.position_in_a, s["o_a"], atol=1e-7)
        np.testing.assert_allclose(r.position_in_b, s["o_b"], atol=1e-7)
        assert r.axis_in_a is not None and r.axis_in_b is not None
        assert abs(abs(float(r.axis_in_a @ s["axis_a"])) - 1) < 1e-10
        assert abs(abs(float(r.axis_in_b @ s["axis_b"])) - 1) < 1e-10
    else:
        assert not r.has_point and r.axis_in_a is None


def test_an_overlapping_hinge_recovered_exactly(rng: np.random.Generator) -> None:
    """``joint --overlap --joint-type hinge``'s bundle: the overlap's hinge rig refined on
    noise-free corners of the shared board gives the hinge's point and axes."""
    s = _scene(rng, True, sigma_px=0.0, joint="hinge")
    n = s["ca"].shape[0]
    Ta = _perturb(s["T_wa_a"], rng, 0.01, 0.005)
    Tb = _perturb(s["T_wb_b"], rng, 0.01, 0.005)
    est = estimate_overlap_rig(Ta, Tb, joint_type="hinge")
    views = {
        c: CameraViews(s[f"c{c}"], np.isfinite(s[f"c{c}"]).all(axis=2), BOARD, s[f"i{c}"] * 1.0)
        for c in ("a", "b")
    }
    ba = bundle_adjust_rig(est.topology, views, est, np.arange(n))
    assert ba.success and ba.rms_px["a"] < 1e-6 and ba.rms_px["b"] < 1e-6
    j = joint_of_rig(ba.estimate, n)
    assert j.joint_type == "hinge"
    np.testing.assert_allclose(j.position_in_a, s["o_a"], atol=1e-7)
    np.testing.assert_allclose(np.asarray(j.position_in_b), s["o_b"], atol=1e-7)
    assert abs(abs(float(j.axis_in["a"] @ s["axis_a"])) - 1) < 1e-10
    assert abs(abs(float(j.axis_in["b"] @ s["axis_b"])) - 1) < 1e-10


@pytest.mark.slow
@pytest.mark.parametrize("overlap", [True, False], ids=["overlap", "general"])
def test_reported_std_matches_the_spread(overlap: bool) -> None:
    """Over seeded trials, the joint's and T_b_a's errors divided by the reported standard
    deviations have unit spread (within sampling error of the trial count). The two-body
    rig's bundle puts them where the retired two-camera bundle did (20 seeds, 0.3 px: the
    joint 11.95 mm general / 6.87 mm overlap RMS for both)."""
    z_joint, z_pose = [], []
    for seed in range(12):
        rng = np.random.default_rng([seed, overlap])
        s = _scene(rng, overlap, sigma_px=0.3)
        ba = _rig_run(s, rng, overlap)
        z_joint.append((ba.position_in_a - s["o_a"]) / np.sqrt(np.diag(ba.covariance_a)))
        T, truth = ba.T_b_a, s["T_b_a"][s["k"]]
        e_rot = se3.rotvec_from_matrix((truth[:3, :3].T @ T[:3, :3])[None])[0]
        e = np.concatenate([e_rot, T[:3, 3] - truth[:3, 3]])
        z_pose.append(e / np.sqrt(np.diag(ba.pose_covariance)))
    for z in (np.array(z_joint), np.array(z_pose)):
        spread = float(np.sqrt(np.mean(z**2)))
        assert 0.6 < spread < 1.5, spread


def test_joint_prior_is_fused(rng: np.random.Generator) -> None:
    s = _scene(rng, overlap=False, sigma_px=0.3)
    free = _rig_run(s, np.random.default_rng(1), overlap=False)
    tight = 1e-8 * np.eye(3)  # 0.1 mm
    prior = JointPrior(s["o_a"], s["o_b"], tight, tight)
    fused = _rig_run(s, np.random.default_rng(1), overlap=False, prior=prior)
    np.testing.assert_allclose(fused.position_in_a, s["o_a"], atol=4e-4)
    assert np.all(np.diag(fused.covariance_a) < 1.01e-8)  # the prior (0.1 mm), hardly more
    assert np.all(np.diag(free.covariance_a) > np.diag(fused.covariance_a))


@pytest.mark.parametrize(
    ("overlap", "models"),
    [(False, ("rational", "fisheye")), (True, ("fisheye", "pinhole"))],
    ids=["general-rational-fisheye", "overlap-fisheye-pinhole"],
)
def test_models_and_partial_views_recover_the_truth(
    rng: np.random.Generator, overlap: bool, models: tuple[str, str]
) -> None:
    """Cameras of different models, each missing 30-70% of its corners (NaN) in half the
    frames (a different part each time): the truth, exactly on noise-free corners."""
    s = _scene(rng, overlap, sigma_px=0.0, models=models)
    s["ca"], s["cb"] = hide_corners(rng, s["ca"]), hide_corners(rng, s["cb"][::-1])[::-1]
    ba = _rig_run(s, rng, overlap, models=models)
    assert ba.success
    _assert_exact(ba, s)
    assert ba.intrinsics_covariance_a.shape == (s["ia"].size,) * 2
    assert ba.intrinsics_std_b.shape == s["ib"].shape


def test_rejects_mismatched_frames(rng: np.random.Generator) -> None:
    s = _scene(rng, overlap=True, sigma_px=0.0, n=6)
    est = estimate_overlap_rig(s["T_wa_a"], s["T_wb_b"])
    views = {
        "a": CameraViews(s["ca"], np.ones(s["ca"].shape[:2], bool), BOARD, s["ia"]),
        "b": CameraViews(s["cb"][:5], np.ones((5, s["cb"].shape[1]), bool), BOARD, s["ib"]),
    }
    with pytest.raises(InputError, match="instants"):
        bundle_adjust_rig(OVERLAP_RIG, views, est, np.arange(5))


def test_long_recordings_are_thinned_evenly() -> None:
    """A bundle adjustment takes at most MAX_BUNDLE_FRAMES frames, evenly spaced among the
    frames used, the reference among them, and says so."""
    from acs_cli.stages.bundle import MAX_BUNDLE_FRAMES, bundle_frames

    used = np.ones(250, bool)
    used[::7] = False
    mask, note = bundle_frames(used, keep=8)
    assert mask.sum() == MAX_BUNDLE_FRAMES and mask[8] and not np.any(mask & ~used)
    assert np.diff(np.flatnonzero(mask)).max() <= 4
    assert note is not None and f"{MAX_BUNDLE_FRAMES} of {used.sum()}" in note
    short = np.ones(30, bool)
    assert bundle_frames(short)[1] is None and bundle_frames(short)[0].all()


def _one_board_rig(seed: int, n: int, joint: str) -> tuple[dict, Any, dict[str, CameraViews]]:
    """A pair seeing one board (``n`` frames, 0.3 px), its pose-based rig (from poses a
    little off, as PnP gives them) and its views with the true intrinsics."""
    from acs_cli.core.rig import rig_topology
    from acs_cli.core.rig_solve import Recordings, estimate_rig

    rng = np.random.default_rng(seed)
    s = _scene(rng, True, sigma_px=0.3, n=n, joint=joint)
    est = estimate_rig(
        rig_topology(["a", "b"], [("j", ["a", "b"], joint)], "a"),
        {c: CameraTrack(_perturb(s[f"T_w{c}_{c}"], rng, 0.002, 0.001), np.ones(n, bool))
         for c in ("a", "b")},
        reference_frame=0,
        recordings=Recordings.single(n, shared_world=True),
        accept_weak=True,
    )  # fmt: skip
    views = {
        c: CameraViews(s[f"c{c}"], np.isfinite(s[f"c{c}"]).all(axis=2), BOARD, s[f"i{c}"])
        for c in ("a", "b")
    }
    return s, est, views


def _pose_z(T: np.ndarray, C: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Errors of ``T`` (rotation, then translation) over their stds from ``C`` ``(6, 6)``."""
    e_rot = se3.rotvec_from_matrix((truth[:3, :3].T @ T[:3, :3])[None])[0]
    return np.concatenate([e_rot, T[:3, 3] - truth[:3, 3]]) / np.sqrt(np.diag(C))


def test_a_rigid_pair_from_three_frames_with_its_intrinsics_held() -> None:
    """Stereo calibration with the intrinsics held (``stereoCalibrate``'s FIX_INTRINSIC):
    from 3 frames of one board, ``T_b_a`` within its reported std (unit spread over seeded
    trials), the intrinsics as given."""
    z = []
    for seed in range(12):
        s, est, views = _one_board_rig(seed, 3, "rigid")
        ba = bundle_adjust_rig(est.topology, views, est, np.arange(3), hold_intrinsics=True)
        assert ba.success and ba.intrinsics_held == "held as asked"
        for c in ("a", "b"):
            np.testing.assert_array_equal(ba.intrinsics[c], s[f"i{c}"])
            assert not ba.intrinsics_std[c].any()
        cam = ba.estimate.cameras["b"]
        z.append(_pose_z(cam.T_cam_ref, cam.covariance, s["T_b_a"][0]))
    spread = float(np.sqrt(np.mean(np.square(z))))
    assert 0.6 < spread < 1.5, spread


@pytest.mark.parametrize(("joint", "fewest"), [("rigid", 1), ("hinge", 2), ("ball", 3)])
def test_the_frames_a_pair_seeing_one_board_needs(joint: str, fewest: int) -> None:
    """The bundle takes as few frames as the unknowns need, and refuses fewer: a rigid pair
    is seen whole in 1 frame; a hinge's angle at every frame leaves its axis and point to 2;
    a ball's rotation leaves 3 rows a frame for its two points (6), and frames that turn
    about one axis do not fix them along it: 3. Under 3 frames the intrinsics are held."""
    s, est, views = _one_board_rig(4, 8, joint)
    for n in range(1, 4):
        if n < fewest:
            with pytest.raises(DegenerateMotionError, match="do not determine the rig"):
                bundle_adjust_rig(est.topology, views, est, np.arange(n))
            continue
        ba = bundle_adjust_rig(est.topology, views, est, np.arange(n))
        assert ba.success
        assert (ba.intrinsics_held is not None) == (n < 3), ba.intrinsics_held
        if ba.intrinsics_held is None:
            continue
        cam = ba.estimate.cameras["b"]
        assert np.abs(_pose_z(cam.T_cam_ref, cam.covariance, s["T_b_a"][0])).max() < 4
