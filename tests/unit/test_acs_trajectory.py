"""Trajectory recovery of an ACS in one frame (acs_cli.core.acs_trajectory), on exact data."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core import acs_trajectory as at
from acs_cli.core import se3
from sample_data_gen.acs_sim import (
    fixed_joint_sequence,
    general_sequence,
    make_rig,
    scale_translations,
)

TOL = 1e-9


@pytest.mark.parametrize("reference", [0, 7, 29])
def test_noiseless_recovery_is_exact(rng: np.random.Generator, reference: int) -> None:
    rig = make_rig(rng)
    seq = general_sequence(rng, rig, n=30)
    traj = at.recover_trajectory(
        seq.T_wa_a, seq.T_wb_b, seq.T_b_a(reference), rig.o_a, rig.o_b, reference
    )
    assert traj.n == 30 and traj.reference == reference and traj.phi_ba == 1.0
    # the joint seen from A and from B coincides at every frame
    np.testing.assert_allclose(traj.joint_from_a, traj.joint_from_b, atol=TOL)
    assert traj.consistency.max() < TOL
    # camera A: the truth relative to its reference pose; B: A's pose times the true T_a_b
    T_r_a_true = se3.invert_transforms(seq.T_wa_a[reference]) @ seq.T_wa_a
    np.testing.assert_allclose(traj.T_r_a, T_r_a_true, atol=TOL)
    np.testing.assert_allclose(traj.T_r_a[reference], np.eye(4), atol=TOL)
    np.testing.assert_allclose(traj.T_r_b, T_r_a_true @ seq.T_a_b, atol=TOL)
    # the joint's pose: A's orientation at the joint
    T_j = traj.T_r_joint
    assert T_j.shape == (30, 4, 4)
    np.testing.assert_allclose(T_j[:, :3, :3], traj.T_r_a[:, :3, :3], atol=TOL)
    np.testing.assert_allclose(T_j[:, :3, 3], traj.joint_from_a, atol=TOL)


def test_unknown_scale_brings_b_to_a_units(rng: np.random.Generator) -> None:
    rig = make_rig(rng)
    seq = general_sequence(rng, rig, n=25)
    mu_a, mu_b = 0.4, 2.5
    T_b_a = seq.T_b_a(3).copy()
    T_b_a[:3, 3] *= mu_b  # B units
    traj = at.recover_trajectory(
        scale_translations(seq.T_wa_a, mu_a),
        scale_translations(seq.T_wb_b, mu_b),
        T_b_a,
        rig.o_a * mu_a,
        rig.o_b * mu_b,
        reference=3,
        phi_ba=mu_b / mu_a,
    )
    metric = at.recover_trajectory(seq.T_wa_a, seq.T_wb_b, seq.T_b_a(3), rig.o_a, rig.o_b, 3)
    assert traj.consistency.max() < TOL
    np.testing.assert_allclose(traj.joint_from_a, mu_a * metric.joint_from_a, atol=TOL)
    np.testing.assert_allclose(traj.T_r_b[:, :3, 3], mu_a * metric.T_r_b[:, :3, 3], atol=TOL)
    np.testing.assert_allclose(traj.T_r_b[:, :3, :3], metric.T_r_b[:, :3, :3], atol=TOL)


def test_wrong_relative_pose_shows_in_consistency(rng: np.random.Generator) -> None:
    rig = make_rig(rng)
    seq = general_sequence(rng, rig, n=20)
    T_b_a = seq.T_b_a(0).copy()
    T_b_a[:3, 3] += [0.01, 0.0, 0.0]
    traj = at.recover_trajectory(seq.T_wa_a, seq.T_wb_b, T_b_a, rig.o_a, rig.o_b)
    assert traj.consistency.min() > 0.005


def test_overlap_relative_pose_and_residuals(rng: np.random.Generator) -> None:
    rig = make_rig(rng)
    seq = general_sequence(rng, rig, n=20, shared_world=True)
    T_b_a = at.overlap_relative_pose(seq.T_wa_a, seq.T_wb_b, reference=4)
    np.testing.assert_allclose(T_b_a, seq.T_b_a(4), atol=TOL)
    res = at.overlap_residuals(seq.T_wa_a, seq.T_wb_b, rig.o_a, rig.o_b)
    assert res.shape == (20,) and res.max() < TOL


def test_fixed_joint_residuals_vanish_on_exact_data(rng: np.random.Generator) -> None:
    rig = make_rig(rng)
    seq = fixed_joint_sequence(rng, rig, n=15)
    assert seq.joint_in_world_a is not None
    res = at.fixed_joint_residuals(seq.T_wa_a, rig.o_a, seq.joint_in_world_a)
    assert res.shape == (15,) and res.max() < TOL
    path = at.joint_path(seq.T_wa_a, rig.o_a)
    np.testing.assert_allclose(path, np.broadcast_to(seq.joint_in_world_a, (15, 3)), atol=TOL)


def test_scaling(rng: np.random.Generator) -> None:
    seq = general_sequence(rng, make_rig(rng), n=6)
    scaled = at.scale_translations(seq.T_wa_a, 3.0)
    np.testing.assert_allclose(scaled[:, :3, 3], 3.0 * seq.T_wa_a[:, :3, 3])
    np.testing.assert_array_equal(scaled[:, :3, :3], seq.T_wa_a[:, :3, :3])


def test_validators_name_the_shape(rng: np.random.Generator) -> None:
    rig = make_rig(rng)
    seq = general_sequence(rng, rig, n=8)
    Ta, Tb, Tba = seq.T_wa_a, seq.T_wb_b, seq.T_b_a(0)
    with pytest.raises(ValueError, match=r"shape \(n, 4, 4\)"):
        at.recover_trajectory(Ta[:, :3], Tb, Tba, rig.o_a, rig.o_b)
    with pytest.raises(ValueError, match="pair one to one"):
        at.recover_trajectory(Ta, Tb[:5], Tba, rig.o_a, rig.o_b)
    with pytest.raises(ValueError, match=r"T_b_a must have shape \(4, 4\)"):
        at.recover_trajectory(Ta, Tb, Tba[:3], rig.o_a, rig.o_b)
    with pytest.raises(ValueError, match=r"position_in_b must have shape \(3,\)"):
        at.recover_trajectory(Ta, Tb, Tba, rig.o_a, rig.o_b[:2])
    with pytest.raises(ValueError, match="reference"):
        at.recover_trajectory(Ta, Tb, Tba, rig.o_a, rig.o_b, reference=8)
    with pytest.raises(ValueError, match="phi_ba"):
        at.recover_trajectory(Ta, Tb, Tba, rig.o_a, rig.o_b, phi_ba=0.0)
    bad = Ta.copy()
    bad[0, :3, :3] *= 2.0
    with pytest.raises(ValueError, match="rotation"):
        at.recover_trajectory(bad, Tb, Tba, rig.o_a, rig.o_b)
    with pytest.raises(ValueError, match="joint_in_world"):
        at.fixed_joint_residuals(Ta, rig.o_a, [np.nan, 0.0, 0.0])
