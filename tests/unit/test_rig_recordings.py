"""Recordings and shared worlds in the one rig engine (issue 19, items 1 and 2).

A shared world is the paper's Algorithm I inside the rig; several recordings share the rig's
geometry; a recording that holds a joint still gives it by Algorithm II."""

from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.rig import rig_topology
from acs_cli.core.rig_solve import CameraTrack, Recordings, estimate_rig
from acs_cli.errors import DegenerateMotionError, InputError
from sample_data_gen import acs_sim
from sample_data_gen import mocap_sim as M

HIP = rig_topology(["pelvis", "femur"], [("hip", ["pelvis", "femur"], "ball")], "pelvis")
LEG = rig_topology(
    ["pelvis", "femur", "tibia"],
    [("hip", ["pelvis", "femur"], "ball"), ("knee", ["femur", "tibia"], "hinge")],
    "pelvis",
)


def _tracks(*trials: dict[str, np.ndarray], unknown: tuple[str, ...] = ()) -> dict:
    """Trials one after the other on one timeline: each body's track (identity, invalid,
    where a trial does not see it)."""
    sizes = [next(iter(t.values())).shape[0] for t in trials]
    n = sum(sizes)
    bodies = sorted({b for t in trials for b in t})
    out = {}
    for b in bodies:
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        v = np.zeros(n, bool)
        at = 0
        for t, m in zip(trials, sizes, strict=True):
            if b in t:
                T[at : at + m] = t[b]
                v[at : at + m] = True
            at += m
        out[b] = CameraTrack(T, v, b in unknown)
    return out


def _recordings(sizes: list[int], shared: list[bool], held: tuple = ()) -> Recordings:
    names = tuple(f"r{i}" for i in range(len(sizes)))
    of = np.concatenate([np.full(m, i) for i, m in enumerate(sizes)])
    return Recordings(names, of, tuple(shared), held)


def test_shared_world_is_algorithm_1_inside_the_rig(rng: np.random.Generator) -> None:
    # a hip trial: the pelvis hardly turns; one lab world for both segments
    trial = M.hip_trial(rng)
    n = trial.times.size
    est = estimate_rig(HIP, _tracks(trial.measured), recordings=Recordings.single(n, True))
    e = est.edges["hip"]
    pair = estimate_joint_overlap(trial.measured["pelvis"], trial.measured["femur"])
    std = float(np.sqrt(np.linalg.eigvalsh(e.position_cov_in["pelvis"])[-1]))
    # as good as the two-camera overlap (here: the same answer) and within its std
    assert np.linalg.norm(e.position_in["pelvis"] - pair.position_in_a) < 0.2 * std
    assert np.linalg.norm(e.position_in["pelvis"] - M.HIP_IN_PELVIS) < 4 * std
    assert np.linalg.norm(e.position_in["femur"] - M.HIP_IN_FEMUR) < 0.005
    # one world: no world-to-world transform estimated
    assert [w.label for w in est.worlds] == ["default"]
    assert np.allclose(est.worlds[0].T_ref_world, np.eye(4))


def test_a_chain_from_two_recordings(rng: np.random.Generator) -> None:
    hip, knee = M.hip_trial(rng), M.knee_trial(rng)
    n, m = hip.times.size, knee.times.size
    est = estimate_rig(
        LEG,
        _tracks(hip.measured, knee.measured),
        recordings=_recordings([n, m], [True, True]),
    )
    assert np.linalg.norm(est.edges["hip"].position_in["pelvis"] - M.HIP_IN_PELVIS) < 0.003
    k = est.edges["knee"]
    u = M.KNEE_AXIS_IN_FEMUR
    assert np.degrees(np.arccos(min(1.0, abs(float(k.axis_in["femur"] @ u))))) < 0.5
    # the hinge point reported is the axis point nearest the femur's origin
    nearest = M.KNEE_IN_FEMUR - (M.KNEE_IN_FEMUR @ u) * u
    assert np.linalg.norm(k.position_in["femur"] - nearest) < 0.003
    # the tibia has no pose at the reference instant (the hip trial's)
    assert est.cameras["tibia"].T_cam_ref is None
    assert est.cameras["femur"].T_cam_ref is not None
    # the knee trial's world is tied to nothing: a choice, not an estimate
    assert [(w.label, w.tied) for w in est.worlds] == [("r0", True), ("r1", False)]


def test_recordings_as_one_timeline_match_each_joint_alone(rng: np.random.Generator) -> None:
    hip, knee = M.hip_trial(rng), M.knee_trial(rng)
    n, m = hip.times.size, knee.times.size
    both = estimate_rig(
        LEG, _tracks(hip.measured, knee.measured), recordings=_recordings([n, m], [True, True])
    )
    alone = estimate_rig(HIP, _tracks(hip.measured), recordings=Recordings.single(n, True))
    a, b = both.edges["hip"].position_in["pelvis"], alone.edges["hip"].position_in["pelvis"]
    # the knee's recording shares only the femur's reference-pose noise level with the hip
    assert np.linalg.norm(a - b) < 2e-5


def test_fixed_joint_recording_then_general_motion(rng: np.random.Generator) -> None:
    # the paper's scenario 2 in one solve: a recording holds the joint still (each camera on
    # its own board), another moves the rig freely; the fixed one enters as priors
    rig = acs_sim.make_rig(rng)
    fixed = acs_sim.fixed_joint_sequence(rng, rig, 30)
    general = acs_sim.general_sequence(rng, rig, 40)
    noisy = {
        s: {
            "a": acs_sim.add_pose_noise(rng, seq.T_wa_a, 0.3, 0.01),
            "b": acs_sim.add_pose_noise(rng, seq.T_wb_b, 0.3, 0.01),
        }
        for s, seq in (("fixed", fixed), ("general", general))
    }
    topo = rig_topology(["a", "b"], [("j", ["a", "b"], "ball")], "a")
    # held still, the fixed recording's frames would try to tie two worlds that a pivot
    # cannot tell apart: the recording adds no rows to the joint, only Algorithm II's prior
    est = estimate_rig(
        topo,
        _tracks(noisy["general"], noisy["fixed"]),
        recordings=_recordings([40, 30], [False, False], ((), ("j",))),
    )
    e = est.edges["j"]
    assert e.frames_used + e.frames_rejected == 40  # the held recording adds no rows
    assert np.linalg.norm(e.position_in["a"] - rig.o_a) < 0.05
    T_b_a = general.T_b_a(0)
    T = est.cameras["b"].T_cam_ref
    assert T is not None
    assert np.linalg.norm(T[:3, 3] - T_b_a[:3, 3]) < 0.1


def test_stereo_pair_from_a_few_views_of_one_board(rng: np.random.Generator) -> None:
    # a rigid edge between two cameras in one world: stereo calibration, from 5 views
    T_b_a = se3.transforms_from_rt(se3.matrix_from_rotvec(np.array([0.02, -0.3, 0.01])),
                                   np.array([-0.12, 0.004, 0.01]))  # fmt: skip
    T_w_a = se3.transforms_from_rt(
        acs_sim.random_rotations(rng, 5, 40.0), rng.uniform(-0.5, 0.5, (5, 3))
    )
    T_w_b = T_w_a @ se3.invert_transforms(T_b_a)
    tracks = {
        "a": CameraTrack(acs_sim.add_pose_noise(rng, T_w_a, 0.05, 0.0005), np.ones(5, bool)),
        "b": CameraTrack(acs_sim.add_pose_noise(rng, T_w_b, 0.05, 0.0005), np.ones(5, bool)),
    }
    topo = rig_topology(["a", "b"], [("s", ["a", "b"], "rigid")], "a")
    est = estimate_rig(topo, tracks, recordings=Recordings.single(5, True))
    T = est.edges["s"].T_q_p
    assert np.linalg.norm(T[:3, 3] - T_b_a[:3, 3]) < 0.003
    assert se3.rotation_angle_deg((T[:3, :3].T @ T_b_a[:3, :3])[None])[0] < 0.2
    # separate worlds need general motion: refused at 5 frames
    with pytest.raises(Exception, match="at least 14"):
        estimate_rig(topo, tracks)


def test_a_shared_world_has_one_scale(rng: np.random.Generator) -> None:
    trial = M.hip_trial(rng, n=60)
    tracks = _tracks(trial.measured, unknown=("femur",))
    with pytest.raises(InputError, match=r"share one world.*one scale"):
        estimate_rig(HIP, tracks, recordings=Recordings.single(60, True))


def test_shared_world_of_unknown_scale(rng: np.random.Generator) -> None:
    # one SfM reconstruction seeing both bodies: one world, one unknown scale; the joint is
    # then in the reconstruction's units
    trial = M.hip_trial(rng)
    n = trial.times.size
    mu = 3.7
    measured = {c: acs_sim.scale_translations(T, mu) for c, T in trial.measured.items()}
    tracks = _tracks(measured, unknown=("pelvis", "femur"))
    est = estimate_rig(HIP, tracks, recordings=Recordings.single(n, True))
    assert np.linalg.norm(est.edges["hip"].position_in["pelvis"] - mu * M.HIP_IN_PELVIS) < 0.01
    assert est.cameras["femur"].scale == 1.0  # one world: one scale, the reference's


@pytest.mark.parametrize("shared", [False, True])
def test_the_analytic_jacobian_matches_differences(
    rng: np.random.Generator, monkeypatch: pytest.MonkeyPatch, shared: bool
) -> None:
    # every joint type, two recordings (the second's worlds shared or not), unknown scale
    from acs_cli.core import rig_solve
    from sample_data_gen.rig_sim import rig_recording

    rec = rig_recording(rng, 40, sigma_rot_deg=0.3, sigma_trans=0.01,
                        unknown_scale=() if shared else ("cam4",))  # fmt: skip
    n = rec.timestamps.size
    tracks = {
        c: CameraTrack(T, np.ones(n, bool), rec.unknown_scale[c]) for c, T in rec.T_wc_c.items()
    }
    recs = _recordings([25, 15], [False, shared])
    seen: list = []
    real = rig_solve.lsq.solve

    def spy(fun, x0, jac=None, **kw):  # type: ignore[no-untyped-def]
        seen.append((fun, jac, x0.copy()))
        return real(fun, x0, jac=jac, **kw)

    monkeypatch.setattr(rig_solve.lsq, "solve", spy)
    # the shared variant treats worlds that differ as one: a misfit, refused after the
    # solves; only the residual function and its Jacobian matter here
    with contextlib.suppress(DegenerateMotionError):
        estimate_rig(rec.topology, tracks, reference_frame=3, recordings=recs)
    fun, jac, x0 = seen[-1]
    x = x0 + 1e-3 * rng.standard_normal(x0.size)
    J = jac(x).toarray()
    h = 1e-6
    D = np.stack([(fun(x + h * e) - fun(x - h * e)) / (2 * h) for e in np.eye(x.size)], axis=1)
    scale = np.maximum(np.abs(D).max(axis=0), 1.0)
    np.testing.assert_allclose(J / scale, D / scale, atol=2e-5)


def test_swapping_a_rigid_edge_or_the_reference_changes_nothing(
    rng: np.random.Generator,
) -> None:
    # a hand-eye pair (separate worlds): T_b_a the same whichever way it is written down
    n = 30
    T_w_a, T_w_b, _ = acs_sim.hand_eye_pair(rng, n)
    tracks = {"a": CameraTrack(T_w_a, np.ones(n, bool)), "b": CameraTrack(T_w_b, np.ones(n, bool))}
    got = []
    for between, ref in (
        (["a", "b"], "a"),
        (["b", "a"], "a"),
        (["a", "b"], "b"),
        (["b", "a"], "b"),
    ):
        est = estimate_rig(rig_topology(["a", "b"], [("r", between, "rigid")], ref), tracks)
        T = est.edges["r"].T_q_p
        got.append(T if between[0] == "a" else se3.invert_transforms(T))
    for T in got[1:]:
        assert np.linalg.norm(T[:3, 3] - got[0][:3, 3]) < 1e-6
        assert (
            se3.rotation_angle_deg((T[:3, :3].T @ got[0][:3, :3])[None])[0] < 1e-4
        )  # solver tolerance


@pytest.mark.parametrize("unknown", [(), ("a",)])
@pytest.mark.parametrize("joint_type", ["ball", "hinge"])
def test_swapping_a_ball_or_hinge_changes_nothing(
    joint_type: str, unknown: tuple[str, ...]
) -> None:
    # the edge's order, the reference camera, or both (issue 19): the point rows' weights are
    # held in the edge's own frame and units, not the reference's
    from sample_data_gen.rig_sim import rig_recording

    rec = rig_recording(np.random.default_rng(5), 60, joints=(("j", ("a", "b"), joint_type),),
                        reference="a", sigma_rot_deg=0.3, sigma_trans=0.005,
                        unknown_scale=unknown)  # fmt: skip
    n = rec.timestamps.size
    tracks = {c: CameraTrack(T, np.ones(n, bool), c in unknown) for c, T in rec.T_wc_c.items()}
    got = []
    for between, ref in (
        (["a", "b"], "a"),
        (["b", "a"], "a"),
        (["a", "b"], "b"),
        (["b", "a"], "b"),
    ):
        e = estimate_rig(rig_topology(["a", "b"], [("j", between, joint_type)], ref), tracks)
        j = e.edges["j"]
        (o, C), u = j.position_own_in["a"], j.axis_in.get("a")
        if u is not None:  # the hinge's line: its point nearest a's centre, its direction
            u = u * np.sign(u[np.argmax(np.abs(u))])
            o = np.concatenate([o - (o @ u) * u, u])
        got.append(o)
    std = float(np.sqrt(np.linalg.eigvalsh(C)[-1]))
    for g in got[1:]:
        # the noise levels settle to 1e-5: ~1e-5 of the std (held in the reference world
        # and units, the weights moved the joint by 5e-4 of it, 2% under unknown scale)
        assert np.abs(g - got[0]).max() < 1e-4 * std


def test_swapping_the_overlap_cameras_changes_nothing(rng: np.random.Generator) -> None:
    # joint --overlap: both cameras in one world, whose frame no unknown turns; A and B
    # exchanged give each camera's joint to rounding
    trial = M.hip_trial(rng)
    a, b = trial.measured["pelvis"], trial.measured["femur"]
    e, s = estimate_joint_overlap(a, b), estimate_joint_overlap(b, a)
    assert s.position_in_b is not None and e.position_in_b is not None
    std = float(np.sqrt(np.linalg.eigvalsh(e.covariance_a)[-1]))
    assert np.linalg.norm(s.position_in_b - e.position_in_a) < 1e-6 * std
    assert np.linalg.norm(s.position_in_a - e.position_in_b) < 1e-6 * std


def test_a_body_whose_world_is_not_tied_to_the_reference_has_no_pose_there(
    tmp_path: Path,
) -> None:
    # review finding: a chain a-b-c-d-e seen as {a, b, d, e} and {b, c, d}; d and e are in
    # the reference recording, but nothing ties their worlds to a's (c is missing there)
    from acs_cli.stages.rig import write_rig_trajectories
    from sample_data_gen.rig_sim import make_edges, rig_recording

    joints = tuple((f"{p}{q}", (p, q), "ball") for p, q in ("ab", "bc", "cd", "de"))
    rng = np.random.default_rng(1)
    edges = make_edges(rng, joints)
    r0, r1 = (
        rig_recording(
            rng,
            40,
            joints=joints,
            reference="a",
            edges=edges,
            sigma_rot_deg=0.05,
            sigma_trans=0.001,
        )
        for _ in range(2)
    )
    tracks = _tracks({c: r0.T_wc_c[c] for c in "abde"}, {c: r1.T_wc_c[c] for c in "bcd"})
    est = estimate_rig(r0.topology, tracks, recordings=_recordings([40, 40], [False, False]))
    assert est.cameras["b"].T_cam_ref is not None
    assert all(est.cameras[c].T_cam_ref is None for c in "cde")
    written = write_rig_trajectories(est, tracks, np.arange(80) / 30.0, tmp_path)
    assert sorted(p.name for p in written) == ["a.tum", "ab.tum", "b.tum"]
