"""``acscal joint --overlap`` through the rig engine (issue 19, item 4): Algorithm I as a
two-body rig in one world (:mod:`acs_cli.core.overlap`), refined on both cameras' corners
of the shared board by the rig's bundle adjustment."""

from __future__ import annotations

import numpy as np
import pytest
from test_bundle_articulated import BOARD, _perturb, _scene

from acs_cli.core.overlap import JOINT, OVERLAP_RIG, estimate_overlap_rig, joint_of_rig
from acs_cli.core.paper import algorithm_1_overlap
from acs_cli.core.rig_bundle import CameraViews, RigBundle, bundle_adjust_rig
from sample_data_gen import acs_sim as sim


def _rig_bundle(s: dict, rng: np.random.Generator) -> RigBundle:
    """The overlap's rig from perturbed poses (as PnP gives them), then its bundle from the
    intrinsics :func:`test_bundle_articulated._run` starts from."""
    Ta = _perturb(s["T_wa_a"], rng, 0.01, 0.005)
    Tb = _perturb(s["T_wb_b"], rng, 0.01, 0.005)
    est = estimate_overlap_rig(Ta, Tb)
    ia0, ib0 = s["ia"].copy(), s["ib"].copy()
    ia0[:5] = ia0[:5] * [1.01, 0.99, 1.0, 1.0, 1.0] + [0, 0, 3, -2, 0.01]
    ib0[:2] *= [0.99, 1.01]
    ib0[5] *= 0.99
    views = {
        c: CameraViews(s[f"c{c}"], np.ones(s[f"c{c}"].shape[:2], bool), BOARD, i0)
        for c, i0 in (("a", ia0), ("b", ib0))
    }
    return bundle_adjust_rig(OVERLAP_RIG, views, est, np.arange(len(Ta)))


def test_the_bundle_recovers_noise_free_corners(rng: np.random.Generator) -> None:
    s = _scene(rng, True, sigma_px=0.0)
    ba = _rig_bundle(s, rng)
    assert ba.success and max(ba.rms_px.values()) < 1e-6
    np.testing.assert_allclose(ba.intrinsics["a"], s["ia"], rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(ba.intrinsics["b"], s["ib"], rtol=1e-6, atol=1e-8)
    j = joint_of_rig(ba.estimate, len(s["ca"]))
    np.testing.assert_allclose(j.position_in_a, s["o_a"], atol=1e-8)
    np.testing.assert_allclose(j.position_in_b, s["o_b"], atol=1e-8)


def test_the_bundle_is_honest() -> None:
    """Over seeded trials (0.3 px of corner noise), the joint's errors over the reported
    stds have unit spread. (The rig's bundle put the joint where the retired two-camera
    bundle did: 1.00x, 20 seeds; tests/unit/test_bundle_articulated.py.)"""
    z = []
    for seed in range(12):
        rng = np.random.default_rng([seed, 1])
        s = _scene(rng, True, sigma_px=0.3)
        ba = _rig_bundle(s, np.random.default_rng([seed, 2]))
        e = ba.estimate.edges[JOINT]
        z.append((e.position_in["a"] - s["o_a"]) / np.sqrt(np.diag(e.position_cov_in["a"])))
    assert 0.6 < float(np.sqrt(np.mean(np.square(z)))) < 1.5


@pytest.mark.parametrize("n", [30])
def test_the_engine_starts_from_algorithm_1(rng: np.random.Generator, n: int) -> None:
    """Noise-free poses: the paper's linear solution and the rig agree with the truth."""
    rig = sim.make_rig(rng)
    seq = sim.general_sequence(rng, rig, n, shared_world=True)
    paper = algorithm_1_overlap(seq.T_wa_a, seq.T_wb_b)
    est = estimate_overlap_rig(seq.T_wa_a, seq.T_wb_b).edges[JOINT]
    for o, got in ((rig.o_a, paper.position_in_a), (rig.o_a, est.position_in["a"])):
        np.testing.assert_allclose(got, o, atol=1e-9)
