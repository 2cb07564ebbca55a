"""Refusals at the paper's noise levels (issue 20, item 2): how often the verdict of
`joint --overlap` and `relpose --unknown-scale` refuses a simulated recording, and why.

Per noise level (the paper's 0.3 deg / 0.0125 m to 2.4 deg / 0.1 m, per axis), ``--trials``
seeded rigs of :mod:`sample_data_gen.acs_sim` with 30 frames of general motion: the refined
estimate, its verdict measures as the commands compute them
(:func:`acs_cli.stages.joint.joint_verdict_measures`,
:func:`acs_cli.stages.relpose.relpose_verdict_measures`), and the verdict (:func:`judge`, no
diagnosis finding: the poses are only noisy). Counted: refusals by the estimator itself
(motion it cannot determine), refusals by the verdict, and results past a refusal level only
in the residual (before issue 20 those were refused with format advice; now weak).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_refusals.py --trials 100   # ~3 min here
"""

# ruff: noqa: E402
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
from types import SimpleNamespace

import numpy as np

from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.quality import judge
from acs_cli.core.relpose import JointPrior, estimate_relpose
from acs_cli.errors import DegenerateMotionError
from acs_cli.stages.joint import joint_verdict_measures
from acs_cli.stages.relpose import relpose_verdict_measures
from sample_data_gen import acs_sim as sim

LEVELS = ((0.3, 0.0125), (0.6, 0.025), (1.2, 0.05), (2.4, 0.1))
N_FRAMES = 30


def _count(measures: list, counts: dict[str, int]) -> None:
    if any(m.past_refusal and m.rule.key == "residual_fraction" for m in measures):
        counts["residual past 25%"] += 1
    try:
        v = judge(measures)
    except DegenerateMotionError:
        counts["refused by the verdict"] += 1
        return
    counts[v.level] += 1


def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--trials", type=int, default=100)
    args = ap.parse_args()
    keys = ("good", "weak", "refused by the verdict", "refused by the estimator",
            "residual past 25%")  # fmt: skip
    print(f"## Verdicts at the paper's noise levels ({args.trials} trials, {N_FRAMES} frames)\n")
    print("| command | noise | " + " | ".join(keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for rot, trans in LEVELS:
        c_ov = dict.fromkeys(keys, 0)
        c_rp = dict.fromkeys(keys, 0)
        for i in range(args.trials):
            rng = np.random.default_rng([2020, i])
            rig = sim.make_rig(rng)
            ov = sim.general_sequence(rng, rig, N_FRAMES, shared_world=True)
            Ta = sim.add_pose_noise(rng, ov.T_wa_a, rot, trans)
            Tb = sim.add_pose_noise(rng, ov.T_wb_b, rot, trans)
            try:
                est = estimate_joint_overlap(Ta, Tb)
                _count(joint_verdict_measures(est, {"ab": np.linalg.solve(Ta, Tb)}), c_ov)
            except DegenerateMotionError:
                c_ov["refused by the estimator"] += 1
            seq = sim.general_sequence(rng, rig, N_FRAMES)
            Ta = sim.add_pose_noise(rng, seq.T_wa_a, rot, trans)
            Tb = sim.add_pose_noise(rng, seq.T_wb_b, rot, trans)
            prior = JointPrior(rig.o_a, rig.o_b, np.eye(3) * 1e-6, np.eye(3) * 1e-6)
            try:
                r = estimate_relpose(Ta, Tb, prior=prior, unknown_scale=True)
                pair = SimpleNamespace(
                    a=SimpleNamespace(T_world_cam=Ta), b=SimpleNamespace(T_world_cam=Tb)
                )
                _count(relpose_verdict_measures(r, pair), c_rp)  # type: ignore[arg-type]
            except DegenerateMotionError:
                c_rp["refused by the estimator"] += 1
        for name, c in (("joint --overlap", c_ov), ("relpose --unknown-scale", c_rp)):
            cells = " | ".join(str(c[k]) for k in keys)
            print(f"| {name} | {rot} deg / {trans} m | {cells} |")


if __name__ == "__main__":
    main()
