"""The refined relative pose (Algorithms III, IV, self-calibration) on seeded recordings:
RMS errors and error over reported std, per kind of joint prior.

Issue 19 moved ``estimate_relpose``'s refined method onto the rig engine (a two-body rig,
:func:`acs_cli.core.relpose.two_body_rig`). Its signature did not change, so this script runs
on commits before and after and compares the two engines on the same seeded data:

    .venv/bin/python benchmarks/bench_relpose.py                 # 30 trials per mode
    .venv/bin/python benchmarks/bench_relpose.py --trials 10

Each trial: a random two-camera rig (:func:`sample_data_gen.acs_sim.make_rig`), 40 frames of
general motion, pose noise 0.6 deg / 2 cm; under unknown scale A's translations are scaled by
0.8 and B's by 3.2. Modes: ``known`` (the exact joint, no covariance), ``known-cov`` (the joint
1 cm off with a 1 cm std), ``scale`` (the exact joint in each camera's own units, 1 cm std),
``scale-metric`` (the joint in metres, both trajectories of unknown scale: ``mu_a``, ``mu_b``
estimated), ``selfcal`` (no joint, unknown scale) and ``selfcal-known`` (no joint, metric).
Printed: RMS of the errors of ``T_b_a`` (deg, mm), of the joint in A and B (mm), of the
relative scale (%) and of ``mu_a`` (%), and RMS error / RMS reported std for ``T_b_a``'s
rotation and translation and the joint in A. Seconds per mode (wall clock, this machine).
"""

# ruff: noqa: E402  (BLAS threads must be set before numpy is imported)
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import time

import numpy as np

from acs_cli.core import se3
from acs_cli.core.relpose import JointPrior, estimate_relpose
from acs_cli.errors import DegenerateMotionError
from sample_data_gen.acs_sim import add_pose_noise, general_sequence, make_rig, scale_translations

MU_A, MU_B = 0.8, 3.2
MODES = ("known", "known-cov", "scale", "scale-metric", "selfcal", "selfcal-known")


def trial(mode: str, seed: int) -> list[float] | None:
    """One seeded trial: errors and stds (see the module doc), or None when refused."""
    rng = np.random.default_rng([seed, 7])
    rig = make_rig(rng)
    g = general_sequence(rng, rig, 40)
    ga = add_pose_noise(rng, g.T_wa_a, 0.6, 0.02)
    gb = add_pose_noise(rng, g.T_wb_b, 0.6, 0.02)
    scale = mode.startswith("scale") or mode == "selfcal"
    mua, mub = (MU_A, MU_B) if scale else (1.0, 1.0)
    sa, sb = scale_translations(ga, mua), scale_translations(gb, mub)
    cov = 1e-4 * np.eye(3)
    prior = {
        "known": JointPrior(rig.o_a, rig.o_b),
        "known-cov": JointPrior(
            rig.o_a + rng.normal(0, 0.01, 3), rig.o_b + rng.normal(0, 0.01, 3), cov, cov
        ),
        "scale": JointPrior(mua * rig.o_a, mub * rig.o_b, mua**2 * cov, mub**2 * cov),
        "scale-metric": JointPrior(rig.o_a, rig.o_b, cov, cov, metric=True),
    }.get(mode)
    try:
        e = estimate_relpose(sa, sb, prior, unknown_scale=scale)
    except DegenerateMotionError:
        return None
    truth = g.T_b_a(0)
    d_rot = se3.rotation_angle_deg(truth[:3, :3].T @ e.T_b_a[:3, :3])
    d_t = np.linalg.norm(e.T_b_a[:3, 3] / mub - truth[:3, 3])
    d_oa = np.linalg.norm(e.position_in_a / mua - rig.o_a)
    d_ob = np.linalg.norm(e.position_in_b / mub - rig.o_b)
    sd_rot = np.degrees(np.sqrt(np.trace(e.covariance[:3, :3])))
    sd_t = np.sqrt(np.trace(e.covariance[3:, 3:])) / mub
    sd_oa = np.sqrt(np.trace(e.covariance_a)) / mua
    d_phi = abs(e.phi_ba - mub / mua) / (mub / mua)
    d_mu = abs(e.mu_a - MU_A) / MU_A if e.mu_a is not None else 0.0
    return [d_rot, 1e3 * d_t, 1e3 * d_oa, 1e3 * d_ob, sd_rot, 1e3 * sd_t, 1e3 * sd_oa,
            100 * d_phi, 100 * d_mu]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=30)
    args = ap.parse_args()
    print("| mode | trials (refused) | T_b_a deg | T_b_a mm | joint in A mm | joint in B mm | "
          "scale % | mu_a % | err/std rot | err/std t | err/std joint A | s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for mode in MODES:
        t0 = time.perf_counter()
        rows = [trial(mode, s) for s in range(args.trials)]
        kept = np.array([r for r in rows if r is not None])
        m = np.sqrt(np.mean(kept**2, axis=0))
        print(
            f"| {mode} | {len(kept)} ({len(rows) - len(kept)}) | {m[0]:.3f} | {m[1]:.1f} | "
            f"{m[2]:.1f} | {m[3]:.1f} | {m[7]:.3f} | {m[8]:.3f} | {m[0] / m[4]:.2f} | "
            f"{m[1] / m[5]:.2f} | {m[2] / m[6]:.2f} | {time.perf_counter() - t0:.1f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
