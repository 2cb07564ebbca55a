"""Reported standard deviations against the spread of the errors, over seeded trials.

For each estimator and quantity it prints RMS(error) / RMS(reported std) (1 is honest),
the RMS of the whitened per-trial errors (z-scores; 1 is honest trial by trial) and the
ratio per axis. Poses get the paper's noise model; 30 frames a recording.

    python benchmarks/bench_uncertainty.py --trials 100 --rot-deg 1.2 --trans 0.05
"""

from __future__ import annotations

import argparse

import numpy as np

import sample_data_gen.acs_sim as sim
from acs_cli.core import se3
from acs_cli.core.joint import estimate_joint_fixed
from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.relpose import JointPrior, estimate_relpose
from acs_cli.errors import DegenerateMotionError

N_FRAMES = 30


def _trials(n: int, rot_deg: float, trans: float) -> dict[str, list[tuple[np.ndarray, ...]]]:
    acc: dict[str, list[tuple[np.ndarray, ...]]] = {}

    def add(key: str, err: object, cov: object) -> None:
        acc.setdefault(key, []).append((np.atleast_1d(err), np.atleast_2d(cov)))

    def noisy(rng: np.random.Generator, T: np.ndarray) -> np.ndarray:
        return np.asarray(sim.add_pose_noise(rng, T, rot_deg, trans))

    for i in range(n):
        rng = np.random.default_rng([909, i])
        rig = sim.make_rig(rng)
        fx = sim.fixed_joint_sequence(rng, rig, N_FRAMES)
        j = estimate_joint_fixed(noisy(rng, fx.T_wa_a), noisy(rng, fx.T_wb_b))
        add("fixed o_a", j.position_in_a - rig.o_a, j.covariance_a)
        add("fixed o_b", j.position_in_b - rig.o_b, j.covariance_b)
        ov = sim.general_sequence(rng, rig, N_FRAMES, shared_world=True)
        jo = estimate_joint_overlap(noisy(rng, ov.T_wa_a), noisy(rng, ov.T_wb_b))
        add("overlap o_a", jo.position_in_a - rig.o_a, jo.covariance_a)
        add("overlap o_b", jo.position_in_b - rig.o_b, jo.covariance_b)
        seq = sim.general_sequence(rng, rig, N_FRAMES)
        Ta, Tb = noisy(rng, seq.T_wa_a), noisy(rng, seq.T_wb_b)
        prior = JointPrior(j.position_in_a, j.position_in_b, j.covariance_a, j.covariance_b)
        truth = np.asarray(seq.T_b_a(0))
        for name, kwargs in (
            ("relpose", {"prior": prior}),
            ("selfcal", {}),
            ("scale", {"prior": prior, "unknown_scale": True}),
        ):
            try:
                r = estimate_relpose(Ta, Tb, **kwargs)  # type: ignore[arg-type]
            except DegenerateMotionError as exc:
                print(f"trial {i} {name}: refused ({exc.message[:80]})")
                continue
            rot = se3.rotvec_from_matrix((truth[:3, :3].T @ r.T_b_a[:3, :3])[None])[0]
            add(f"{name} R", rot, r.covariance[:3, :3])
            add(f"{name} t", r.T_b_a[:3, 3] - truth[:3, 3], r.covariance[3:, 3:])
            add(f"{name} o_a", r.position_in_a - rig.o_a, r.covariance_a)
            if name == "scale":
                add("scale phi", r.phi_ba - 1.0, r.phi_std**2)
    return acc


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trials", type=int, default=100)
    p.add_argument("--rot-deg", type=float, default=1.2)
    p.add_argument("--trans", type=float, default=0.05)
    args = p.parse_args()
    acc = _trials(args.trials, args.rot_deg, args.trans)
    print(f"{args.trials} trials, noise {args.rot_deg} deg / {args.trans} m, {N_FRAMES} frames")
    print(f"{'quantity':14s} {'RMS err':>9s} {'RMS std':>9s} {'ratio':>6s} {'z-RMS':>6s}  per axis")
    for key, rows in acc.items():
        e = np.array([r[0] for r in rows])
        C = np.array([r[1] for r in rows])
        var = np.diagonal(C, axis1=1, axis2=2)
        rms_err, rms_std = np.sqrt(np.mean(e**2)), np.sqrt(np.mean(var))
        z = np.linalg.solve(np.linalg.cholesky(C), e[..., None])[..., 0]
        axes = np.sqrt(np.mean(e**2, axis=0)) / np.sqrt(np.mean(var, axis=0))
        print(
            f"{key:14s} {rms_err:9.4g} {rms_std:9.4g} {rms_err / rms_std:6.3f} "
            f"{np.sqrt(np.mean(z**2)):6.3f}  {np.round(axes, 2).tolist()}"
        )


if __name__ == "__main__":
    main()
