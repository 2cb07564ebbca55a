"""The paper's algorithms, one function each, agree with the estimators' paper method."""

from __future__ import annotations

import numpy as np

from acs_cli.core import paper
from sample_data_gen.acs_sim import (
    fixed_joint_sequence,
    general_sequence,
    make_rig,
    scale_translations,
)


def test_each_algorithm_recovers_a_noiseless_rig(rng: np.random.Generator) -> None:
    rig = make_rig(rng)
    ov = general_sequence(rng, rig, 30, shared_world=True)
    j1 = paper.algorithm_1_overlap(ov.T_wa_a, ov.T_wb_b)
    np.testing.assert_allclose(j1.position_in_a, rig.o_a, atol=1e-8)
    fj = fixed_joint_sequence(rng, rig, 30)
    j2 = paper.algorithm_2_fixed_joint(fj.T_wa_a, fj.T_wb_b)
    np.testing.assert_allclose(j2.position_in_b, rig.o_b, atol=1e-8)
    gen = general_sequence(rng, rig, 30)
    r3 = paper.algorithm_3_relative_pose(gen.T_wa_a, gen.T_wb_b, rig.o_a)
    np.testing.assert_allclose(r3.T_b_a, gen.T_b_a(0), atol=1e-7)
    r4 = paper.algorithm_4_unknown_scale(
        gen.T_wa_a, scale_translations(gen.T_wb_b, 2.5), rig.o_a, reference=4
    )
    assert abs(r4.phi_ba - 2.5) < 1e-7
    assert r4.method == "paper"
