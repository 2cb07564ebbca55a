"""Wall-clock benchmark of every estimator on seeded synthetic data.

For each number of frames ``n`` one rig and its sequences are simulated (pose noise
1.2 deg / 0.05 m, as in the paper's section 5), then every estimator is timed as the best
of ``--repeat`` runs (``time.perf_counter``). Data generation is not timed.

    .venv/bin/python benchmarks/bench_estimators.py                  # full sizes
    .venv/bin/python benchmarks/bench_estimators.py --quick          # n = 30, 1000
    .venv/bin/python benchmarks/bench_estimators.py --out benchmarks/results.md

Prints a Markdown table (rows: estimators, columns: n, cells: seconds) with the cost per
frame at the largest ``n`` and the machine it ran on. Each result is also checked against
the truth: a joint farther than ``--tolerance`` metres is reported on stderr (a sign of a
broken set-up; the paper's methods are expected to be off by centimetres at this noise).
"""

# ruff: noqa: E402  (BLAS threads must be set before numpy is imported)
from __future__ import annotations

import os

# as the acscal command does (acs_cli/cli/__init__.py): one BLAS thread unless told otherwise
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import datetime as dt
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy

from acs_cli.core.joint import estimate_joint_fixed
from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.paper import algorithm_2_fixed_joint
from acs_cli.core.relpose import JointPrior, estimate_relpose
from sample_data_gen.acs_sim import (
    add_pose_noise,
    fixed_joint_sequence,
    general_sequence,
    make_rig,
    scale_translations,
)

SIGMA_ROT_DEG = 1.2
SIGMA_TRANS = 0.05
#: Unknown scales of trajectories A and B (the paper's mu_A, mu_B).
MU_A, MU_B = 0.8, 3.2
#: Prior covariance of the joint (m^2) for the refined relative pose.
PRIOR_VAR = 1e-4
FULL_SIZES = (30, 100, 1000, 10000, 100000)
_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
_HAS_LOAD = hasattr(os, "getloadavg")
QUICK_SIZES = (30, 1000)


@dataclass
class Case:
    """One estimator on one data set: ``run()`` returns the joint in A's frame (metres)."""

    name: str
    run: Callable[[], np.ndarray]
    truth: np.ndarray


def make_cases(n: int, seed: int) -> list[Case]:
    """Seeded data for ``n`` frames and the estimators to time on it."""
    rng = np.random.default_rng([seed, n])
    rig = make_rig(rng)
    o_a, o_b = rig.o_a, rig.o_b

    def noisy(T: np.ndarray) -> np.ndarray:
        return add_pose_noise(rng, T, SIGMA_ROT_DEG, SIGMA_TRANS)

    fixed = fixed_joint_sequence(rng, rig, n)
    fa = noisy(fixed.T_wa_a)
    overlap = general_sequence(rng, rig, n, shared_world=True)
    va, vb = noisy(overlap.T_wa_a), noisy(overlap.T_wb_b)
    general = general_sequence(rng, rig, n)
    ga, gb = noisy(general.T_wa_a), noisy(general.T_wb_b)
    sa, sb = scale_translations(ga, MU_A), scale_translations(gb, MU_B)

    cov = PRIOR_VAR * np.eye(3)
    exact = JointPrior(o_a, o_b)
    tight = JointPrior(o_a, o_b, cov, cov)
    # under unknown scale a (non-metric) prior is in each trajectory's own units
    exact_s = JointPrior(MU_A * o_a, MU_B * o_b)
    tight_s = JointPrior(MU_A * o_a, MU_B * o_b, MU_A**2 * cov, MU_B**2 * cov)

    def rel(Ta, Tb, prior, method, scale=False, mu=1.0):
        def run() -> np.ndarray:
            est = estimate_relpose(Ta, Tb, prior, unknown_scale=scale, method=method)
            return est.position_in_a / mu

        return run

    def fix(method):
        fit = algorithm_2_fixed_joint if method == "paper" else estimate_joint_fixed
        return lambda: fit(fa).position_in_a

    def ovl(method):
        return lambda: estimate_joint_overlap(va, vb, method=method).position_in_a

    return [
        Case("fixed-joint paper", fix("paper"), o_a),
        Case("fixed-joint refined", fix("refined"), o_a),
        Case("overlap paper", ovl("paper"), o_a),
        Case("overlap refined", ovl("refined"), o_a),
        Case("relpose paper", rel(ga, gb, exact, "paper"), o_a),
        Case("relpose refined", rel(ga, gb, tight, "refined"), o_a),
        Case("unknown-scale paper", rel(sa, sb, exact_s, "paper", True, MU_A), o_a),
        Case("unknown-scale refined", rel(sa, sb, tight_s, "refined", True, MU_A), o_a),
        Case("self-calibration", rel(sa, sb, None, "refined", True, MU_A), o_a),
    ]


def best_time(fn: Callable[[], np.ndarray], repeat: int) -> tuple[float, np.ndarray]:
    """Best wall-clock time of ``repeat`` calls and the last result."""
    best = float("inf")
    out = np.zeros(3)
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def machine_info() -> str:
    threads = {k: os.environ[k] for k in _THREAD_VARS if k in os.environ}
    load = ", load average {:.2f} {:.2f} {:.2f}".format(*os.getloadavg()) if _HAS_LOAD else ""
    return (
        f"{platform.platform()}, Python {platform.python_version()}, numpy {np.__version__}, "
        f"scipy {scipy.__version__}, {os.cpu_count()} CPUs{load}, BLAS threads "
        + (", ".join(f"{k}={v}" for k, v in threads.items()) or "default")
    )


def render(sizes: list[int], names: list[str], times: dict[tuple[str, int], float]) -> str:
    nmax = max(sizes)
    head = ["estimator", *(f"n={n}" for n in sizes), f"us/frame @ n={nmax}"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name in names:
        cells = [f"{times[name, n]:.3g}" for n in sizes]
        per_frame = times[name, nmax] / nmax * 1e6
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {per_frame:.3g} |")
    return "\n".join(lines)


def parse_sizes(text: str) -> list[int]:
    sizes = [int(s) for s in text.split(",") if s.strip()]
    if not sizes or min(sizes) < 14:
        raise argparse.ArgumentTypeError("sizes must be >= 14 (self-calibration's minimum)")
    return sizes


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=parse_sizes, default=list(FULL_SIZES), help="e.g. 30,1000")
    ap.add_argument("--repeat", type=int, default=3, help="runs per cell; the best is kept")
    ap.add_argument("--quick", action="store_true", help=f"sizes {QUICK_SIZES}")
    ap.add_argument("--out", type=Path, help="also write the Markdown report here")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--tolerance", type=float, default=0.25, help="joint error warning (m)")
    args = ap.parse_args(argv)
    sizes = list(QUICK_SIZES) if args.quick else args.sizes

    make_cases(30, args.seed)[0].run()  # warm-up: imports and first-call costs
    times: dict[tuple[str, int], float] = {}
    names: list[str] = []
    failures = []
    for n in sizes:
        for case in make_cases(n, args.seed):
            if case.name not in names:
                names.append(case.name)
            t, o_a = best_time(case.run, args.repeat)
            times[case.name, n] = t
            err = float(np.linalg.norm(o_a - case.truth))
            line = f"  n={n:>7} {case.name:<22} {t:9.4f} s  joint error {err:.4f} m"
            print(line, file=sys.stderr)
            if not err < args.tolerance:
                failures.append(f"{case.name} at n={n}: joint error {err:.3f} m")

    report = "\n".join(
        [
            f"Seconds (best of {args.repeat}); pose noise {SIGMA_ROT_DEG} deg / {SIGMA_TRANS} m, "
            f"seed {args.seed}.",
            "",
            render(sizes, names, times),
            "",
            f"Machine: {machine_info()}",
            f"Date: {dt.datetime.now().astimezone().isoformat(timespec='seconds')}",
        ]
    )
    sys.stderr.flush()
    print(report, flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text("# Estimator benchmark\n\n" + report + "\n")
    for f in failures:
        print(f"WARNING: {f}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
