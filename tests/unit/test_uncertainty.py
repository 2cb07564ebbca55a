"""Honest uncertainty: over seeded simulated trials, the spread of each estimate's error
agrees with the standard deviation it reports, within 25% (issue 4, section 3).

For every quantity the measure is ``RMS(error) / RMS(reported std)`` over the trials,
pooled over its components (a vector's three axes). With 40 trials the sampling error of
that ratio is about 5%; the bound is 25%.

A caveat measured here and documented in docs/accuracy.md: the rotation of ``T_b_a`` is
honest on average, but its per-trial standard deviation rests on the rotation-noise level
estimated from that trial's 30 poses, which is weakly determined, so per-trial z-scores
spread wider (RMS about 1.7) than a perfectly known noise level would give.
"""

from __future__ import annotations

import numpy as np
import pytest

import sample_data_gen.acs_sim as sim
from acs_cli.core import se3
from acs_cli.core.bundle import intrinsics_vector
from acs_cli.core.camera_models import camera_model
from acs_cli.core.joint import estimate_joint_fixed, estimate_pivot
from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.relpose import JointPrior, estimate_relpose
from acs_cli.core.rig_bundle import bundle_adjust_fixed_joint

N_TRIALS = 40
N_FRAMES = 30
SIGMA_ROT_DEG = 1.2
SIGMA_TRANS = 0.05
TOLERANCE = 0.25


def _noisy(rng: np.random.Generator, T: np.ndarray) -> np.ndarray:
    return np.asarray(sim.add_pose_noise(rng, T, SIGMA_ROT_DEG, SIGMA_TRANS))


def _rotation_error(T_est: np.ndarray, T_true: np.ndarray) -> np.ndarray:
    """Right perturbation of the estimate's rotation, as the covariance is defined."""
    return se3.rotvec_from_matrix((T_true[:3, :3].T @ T_est[:3, :3])[None])[0]


def _pose_trials() -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    out: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}

    def add(key: str, err: np.ndarray, cov: np.ndarray) -> None:
        out.setdefault(key, []).append((np.atleast_1d(err), np.atleast_2d(cov)))

    for i in range(N_TRIALS):
        rng = np.random.default_rng([909, i])
        rig = sim.make_rig(rng)
        fixed = sim.fixed_joint_sequence(rng, rig, N_FRAMES)
        j = estimate_joint_fixed(_noisy(rng, fixed.T_wa_a), _noisy(rng, fixed.T_wb_b))
        assert j.position_in_b is not None and j.covariance_b is not None
        add("fixed joint: o_a", j.position_in_a - rig.o_a, j.covariance_a)
        add("fixed joint: o_b", j.position_in_b - rig.o_b, j.covariance_b)
        ov = sim.general_sequence(rng, rig, N_FRAMES, shared_world=True)
        jo = estimate_joint_overlap(_noisy(rng, ov.T_wa_a), _noisy(rng, ov.T_wb_b))
        assert jo.position_in_b is not None and jo.covariance_b is not None
        add("overlap: o_a", jo.position_in_a - rig.o_a, jo.covariance_a)
        add("overlap: o_b", jo.position_in_b - rig.o_b, jo.covariance_b)
        seq = sim.general_sequence(rng, rig, N_FRAMES)
        Ta, Tb = _noisy(rng, seq.T_wa_a), _noisy(rng, seq.T_wb_b)
        prior = JointPrior(j.position_in_a, j.position_in_b, j.covariance_a, j.covariance_b)
        truth = np.asarray(seq.T_b_a(0))
        for name, kwargs in (
            ("relpose", {"prior": prior}),
            ("self-calibration", {}),
            ("unknown scale", {"prior": prior, "unknown_scale": True}),
        ):
            r = estimate_relpose(Ta, Tb, **kwargs)  # type: ignore[arg-type]
            add(f"{name}: R_b_a", _rotation_error(r.T_b_a, truth), r.covariance[:3, :3])
            add(f"{name}: t_b_a", r.T_b_a[:3, 3] - truth[:3, 3], r.covariance[3:, 3:])
            add(f"{name}: o_a", r.position_in_a - rig.o_a, r.covariance_a)
            add(f"{name}: o_b", r.position_in_b - rig.o_b, r.covariance_b)
            if kwargs.get("unknown_scale"):
                add(f"{name}: phi_ba", np.array([r.phi_ba - 1.0]), np.array([[r.phi_std**2]]))
    return out


@pytest.fixture(scope="module")
def pose_trials() -> dict[str, list[tuple[np.ndarray, np.ndarray]]]:
    return _pose_trials()


def _ratio(trials: list[tuple[np.ndarray, np.ndarray]]) -> float:
    err = np.array([e for e, _ in trials])
    var = np.array([np.diag(c) for _, c in trials])
    return float(np.sqrt(np.mean(err**2)) / np.sqrt(np.mean(var)))


QUANTITIES = [
    "fixed joint: o_a", "fixed joint: o_b", "overlap: o_a", "overlap: o_b",
    *(f"{m}: {q}" for m in ("relpose", "self-calibration", "unknown scale")
      for q in ("R_b_a", "t_b_a", "o_a", "o_b")),
    "unknown scale: phi_ba",
]  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("quantity", QUANTITIES)
def test_reported_std_matches_the_error_spread(
    pose_trials: dict[str, list[tuple[np.ndarray, np.ndarray]]], quantity: str
) -> None:
    # got (40 trials): 0.86-1.08 for every quantity
    ratio = _ratio(pose_trials[quantity])
    assert abs(ratio - 1.0) <= TOLERANCE, f"{quantity}: RMS error / RMS std = {ratio:.3f}"


@pytest.mark.slow
def test_bundle_adjustment_std_matches_the_error_spread() -> None:
    """The fixed-joint bundle adjustment's joint and focal-length standard deviations (from
    its Jacobian and the estimated pixel noise) over seeded trials of corner noise."""
    board = np.array([[c * 0.04, r * 0.04, 0.0] for r in range(6) for c in range(9)])
    rng = np.random.default_rng(77)
    K = np.array([[900.0, 0, 512], [0, 905.0, 384], [0, 0, 1]])
    dist = np.array([-0.2, 0.05, 1e-3, -1e-3, 0.0])
    intr = intrinsics_vector(K, dist)
    o = np.array([0.05, -0.2, -0.12])
    p_w = board.mean(axis=0) - np.array([0, 0, 0.75]) + o
    R = se3.matrix_from_rotvec(rng.normal(0, 0.2, (20, 3)))
    T = se3.transforms_from_rt(R, p_w - se3.rotate(R, o))
    x_cam = np.einsum("nji,mj->nmi", R, board - p_w) + o
    px = camera_model("pinhole").project(x_cam, intr)
    errs, stds = [], []
    for _ in range(N_TRIALS):
        obs = px + rng.normal(0, 0.1, px.shape)
        ba = bundle_adjust_fixed_joint(
            obs, np.ones(obs.shape[:2], bool), board, intr * 1.002, T, o + 0.003, p_w
        )
        errs.append(np.r_[ba.joint_in_cam - o, ba.intrinsics[0] - intr[0]])
        stds.append(np.r_[ba.joint_std, np.sqrt(ba.intrinsics_covariance[0, 0])])
    ratio = np.sqrt(np.mean(np.square(errs), axis=0)) / np.sqrt(np.mean(np.square(stds), axis=0))
    # got: [0.96 1.05 1.02 1.04]
    assert np.all(np.abs(ratio - 1.0) <= TOLERANCE), ratio


def test_pivot_alone_is_honest_too() -> None:
    """One camera's fixed-joint estimate (the paper's pivot calibration, refined)."""
    errs, variances = [], []
    for i in range(N_TRIALS):
        rng = np.random.default_rng([910, i])
        rig = sim.make_rig(rng)
        seq = sim.fixed_joint_sequence(rng, rig, N_FRAMES)
        est = estimate_pivot(_noisy(rng, seq.T_wa_a), "refined", "A")
        errs.append(est.position_in_cam - rig.o_a)
        variances.append(np.diag(est.covariance))
    ratio = float(np.sqrt(np.mean(np.square(errs))) / np.sqrt(np.mean(variances)))
    assert abs(ratio - 1.0) <= TOLERANCE, ratio
