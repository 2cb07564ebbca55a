"""What the poses do not fit (issue 13 item 2): detection and false-diagnosis rates of
:mod:`acs_cli.core.diagnose`, and the cost of a diagnosis.

Per trial (seeded): a random rig (``make_rig``, joint 0.1-0.5 m from each camera), ``n``
frames uniform in 30-100, pose noise uniform in 0.2-1 deg and 1-5 mm per axis. Recordings:

- fixed joint: ``fixed_joint_sequence``; camera A diagnosed (``diagnose_fixed_joint``);
  the joint file of the relative-pose cases is ``estimate_joint_fixed`` on it (A and B),
  with its covariances;
- overlap: ``general_sequence(shared_world=True)`` (``diagnose_overlap``);
- relative pose: ``general_sequence`` (``diagnose_relpose``, known scale, the joint file);
  the clocks' case: ``smooth_general_sequence`` at 10 Hz with B's clock 0.1-0.3 s off
  (either sign), both trajectories given with timestamps.

Each recording is fitted as given (clean) and with one cause injected; the diagnosis runs on
every fit (whether or not :func:`fit_is_suspicious` would trigger it). Printed (Markdown),
per case: trials, fits that failed (a degenerate motion error: no residual to diagnose),
the trigger rates (residual above 5% of the length scale; above 3x the RMS the simulated
noise implies), the share diagnosed with the injected cause and input (for clean cases:
any diagnosis is a false one), and the diagnosis's median and largest run time (wall clock,
and CPU time of this process in brackets: the machine may be shared).

    .venv/bin/python benchmarks/bench_diagnose.py               # 20 trials
    .venv/bin/python benchmarks/bench_diagnose.py --trials 3    # a smoke run

Results (2026-11-24, 20 trials, seed 0, 2 shared CPUs): every injected cause named with its
input in every trial (fixed joint, overlap, relative pose), except B's clock on recordings
under 50 frames at 10 Hz (too short for the offset search: 90% over all lengths, one named
``joint_from_another_rig``); no diagnosis on any of the 80 clean fits, 10% of the clean
fixed-joint fits (4-5 mm noise on a joint 0.1-0.2 m away) above the 5% trigger. A
diagnosis takes 0.01-0.03 s CPU for a fixed joint or overlap, 0.3-0.6 s for a relative pose
(median; up to 2.8 s when a camera's translations are in other units).
"""

# ruff: noqa: E402  (BLAS threads must be set before numpy is imported)
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from acs_cli.core import se3
from acs_cli.core.diagnose import (
    NOISE_FACTOR,
    Diagnosis,
    TimedPair,
    diagnose_fixed_joint,
    diagnose_overlap,
    diagnose_relpose,
    expected_residual_rms,
    fit_is_suspicious,
    pair_length_scale,
    reordered_quaternions,
    scaled_prior,
)
from acs_cli.core.joint import estimate_joint_fixed, estimate_pivot
from acs_cli.core.overlap import estimate_joint_overlap
from acs_cli.core.quality import length_scale
from acs_cli.core.relpose import JointPrior, estimate_relpose
from acs_cli.errors import DegenerateMotionError
from sample_data_gen.acs_sim import (
    add_pose_noise,
    fixed_joint_sequence,
    general_sequence,
    make_rig,
    scale_translations,
    smooth_general_sequence,
)

JOINT_RANGE = (0.1, 0.5)
FRAMES = (30, 100)
ROT_NOISE_DEG = (0.2, 1.0)
TRANS_NOISE = (0.001, 0.005)
CLOCK_OFFSET_S = (0.1, 0.3)
CLOCK_FPS = 10.0


@dataclass(frozen=True)
class Row:
    """One diagnosis: the case, what was expected and found, the trigger, the time."""

    scenario: str
    case: str
    expected: tuple[str, str] | None
    found: tuple[str, str] | None
    failed: bool
    by_scale: bool
    by_noise: bool
    seconds: float
    cpu_seconds: float
    n: int


def _found(d: Diagnosis | None) -> tuple[str, str] | None:
    return None if d is None else (d.cause, d.input)


def _row(
    scenario: str,
    case: str,
    expected: tuple[str, str] | None,
    fit: Callable[[], tuple[float, float, float]],
    diagnose: Callable[[float], Diagnosis | None],
    n: int,
) -> Row:
    """Fit (residual RMS, length scale, expected RMS), then time the diagnosis."""
    try:
        rms, scale, expected_rms = fit()
    except DegenerateMotionError:
        return Row(scenario, case, expected, None, True, False, False, 0.0, 0.0, n)
    t0, c0 = time.perf_counter(), time.process_time()
    d = diagnose(rms)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    return Row(
        scenario,
        case,
        expected,
        _found(d),
        False,
        fit_is_suspicious(rms, scale),
        rms > NOISE_FACTOR * expected_rms,
        seconds,
        cpu,
        n,
    )


def _fixed_rows(T: np.ndarray, sr: float, st: float, n: int) -> list[Row]:
    rows = []
    for case, data, expected in (
        ("clean", T, None),
        ("A written wxyz", reordered_quaternions(T, 1), ("quaternion_order_wxyz", "a")),
        ("A written xyzw, read wxyz", reordered_quaternions(T, -1), ("quaternion_order_xyzw", "a")),
    ):  # fmt: skip

        def fit(data: np.ndarray = data) -> tuple[float, float, float]:
            p = estimate_pivot(data, "refined", "camera A")
            o = p.position_in_cam
            return p.residual_rms, length_scale(o, data), expected_residual_rms(sr, st, o)

        def diagnose(rms: float, data: np.ndarray = data) -> Diagnosis | None:
            return diagnose_fixed_joint(data, quaternion_source=True, current_rms=rms)

        rows.append(_row("fixed joint", case, expected, fit, diagnose, n))
    return rows


def _overlap_rows(Ta: np.ndarray, Tb: np.ndarray, sr: float, st: float, n: int) -> list[Row]:
    rows = []
    for case, A, B, expected in (
        ("clean", Ta, Tb, None),
        ("B written wxyz", Ta, reordered_quaternions(Tb, 1), ("quaternion_order_wxyz", "b")),
        ("A inverted", se3.invert_transforms(Ta), Tb, ("inverted_poses", "a")),
        ("B in mm", Ta, scale_translations(Tb, 1e3), ("units_mm_vs_m", "b")),
    ):  # fmt: skip

        def fit(A: np.ndarray = A, B: np.ndarray = B) -> tuple[float, float, float]:
            e = estimate_joint_overlap(A, B)
            o_b = e.position_in_b if e.position_in_b is not None else np.zeros(3)
            scale = pair_length_scale(A, B, e.position_in_a, o_b)
            exp = expected_residual_rms(sr, st, np.stack([e.position_in_a, o_b]))
            return e.residual_rms["ab"], scale, exp

        def diagnose(rms: float, A: np.ndarray = A, B: np.ndarray = B) -> Diagnosis | None:
            return diagnose_overlap(A, B, quaternion_source=(True, True), current_rms=rms)

        rows.append(_row("overlap", case, expected, fit, diagnose, n))
    return rows


def _relpose_case(
    case: str,
    A: np.ndarray,
    B: np.ndarray,
    prior: JointPrior,
    expected: tuple[str, str] | None,
    sr: float,
    st: float,
    n: int,
    timed: TimedPair | None = None,
) -> Row:
    def fit() -> tuple[float, float, float]:
        e = estimate_relpose(A, B, prior)
        scale = pair_length_scale(A, B, e.position_in_a, e.position_in_b)
        exp = expected_residual_rms(sr, st, np.stack([e.position_in_a, e.position_in_b]))
        return e.residual_rms, scale, exp

    def diagnose(rms: float) -> Diagnosis | None:
        return diagnose_relpose(A, B, prior, current_rms=rms, timed=timed)

    return _row("relative pose", case, expected, fit, diagnose, n)


def _relpose_rows(
    Ta: np.ndarray,
    Tb: np.ndarray,
    prior: JointPrior,
    other: JointPrior,
    sr: float,
    st: float,
    n: int,
) -> list[Row]:
    inv = se3.invert_transforms
    wxyz = "quaternion_order_wxyz"
    cases = [
        ("clean", Ta, Tb, prior, None),
        ("A written wxyz", reordered_quaternions(Ta, 1), Tb, prior, (wxyz, "a")),
        ("B written xyzw, read wxyz", Ta, reordered_quaternions(Tb, -1), prior,
         ("quaternion_order_xyzw", "b")),
        ("A and B written wxyz", reordered_quaternions(Ta, 1), reordered_quaternions(Tb, 1),
         prior, (wxyz, "ab")),
        ("A inverted", inv(Ta), Tb, prior, ("inverted_poses", "a")),
        ("B inverted", Ta, inv(Tb), prior, ("inverted_poses", "b")),
        ("A and B inverted", inv(Ta), inv(Tb), prior, ("inverted_poses", "ab")),
        ("A in mm", scale_translations(Ta, 1e3), Tb, prior, ("units_mm_vs_m", "a")),
        ("B in km", Ta, scale_translations(Tb, 1e-3), prior, ("units_mm_vs_m", "b")),
        ("joint file in mm", Ta, Tb, scaled_prior(prior, 1e3), ("units_mm_vs_m", "joint")),
        ("joint file of another rig", Ta, Tb, other, ("joint_from_another_rig", "joint")),
    ]  # fmt: skip
    return [_relpose_case(c, A, B, p, e, sr, st, n) for c, A, B, p, e in cases]


def _prior(Ta: np.ndarray, Tb: np.ndarray) -> JointPrior:
    """The joint file of a fixed-joint session: positions and covariances."""
    j = estimate_joint_fixed(Ta, Tb)
    return JointPrior(j.position_in_a, j.position_in_b, j.covariance_a, j.covariance_b)


def trial(seed: int, k: int, clean_clock: bool) -> list[Row]:
    """All the cases of one seeded trial."""
    rng = np.random.default_rng([seed, k])
    rig = make_rig(rng, JOINT_RANGE)
    other_rig = make_rig(rng, JOINT_RANGE)
    n = int(rng.integers(FRAMES[0], FRAMES[1] + 1))
    sr = float(rng.uniform(*ROT_NOISE_DEG))
    st = float(rng.uniform(*TRANS_NOISE))

    def noisy(T: np.ndarray) -> np.ndarray:
        return add_pose_noise(rng, T, sr, st)

    fixed = fixed_joint_sequence(rng, rig, n)
    fa, fb = noisy(fixed.T_wa_a), noisy(fixed.T_wb_b)
    rows = _fixed_rows(fa, sr, st, n)
    other_fixed = fixed_joint_sequence(rng, other_rig, n)
    try:
        prior = _prior(fa, fb)
        other = _prior(noisy(other_fixed.T_wa_a), noisy(other_fixed.T_wb_b))
    except DegenerateMotionError:
        return rows
    ov = general_sequence(rng, rig, n, shared_world=True)
    rows += _overlap_rows(noisy(ov.T_wa_a), noisy(ov.T_wb_b), sr, st, n)
    gen = general_sequence(rng, rig, n)
    rows += _relpose_rows(noisy(gen.T_wa_a), noisy(gen.T_wb_b), prior, other, sr, st, n)
    offset = float(rng.choice([-1.0, 1.0]) * rng.uniform(*CLOCK_OFFSET_S))
    clocks: list[tuple[str, float, tuple[str, str] | None]] = [
        ("B's clock off by 0.1-0.3 s", offset, ("unsynchronised", "ab"))
    ]
    if clean_clock:
        clocks.append(("clean, with timestamps", 0.0, None))
    for case, dt, expected in clocks:
        seq = smooth_general_sequence(rng, rig, n, fps=CLOCK_FPS, time_offset_s=dt)
        A, B = noisy(seq.T_wa_a), noisy(seq.T_wb_b)
        timed = TimedPair(seq.timestamps, A, seq.timestamps, B)
        rows.append(_relpose_case(case, A, B, prior, expected, sr, st, n, timed))
    return rows


def _pct(k: int, m: int) -> str:
    return f"{100.0 * k / m:.0f}%" if m else "-"


def render(rows: Sequence[Row]) -> str:
    groups: dict[tuple[str, str], list[Row]] = defaultdict(list)
    for r in rows:
        groups[r.scenario, r.case].append(r)
        if r.expected == ("unsynchronised", "ab") and r.n >= 50:
            groups[r.scenario, r.case + " (n >= 50)"].append(r)
    head = [
        "scenario",
        "case",
        "trials",
        "fit failed",
        "trigger: 5% of scale",
        "trigger: 3x noise",
        "right cause",
        "false or wrong",
        "median s (CPU)",
        "max s (CPU)",
    ]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for (scenario, case), rs in groups.items():
        ok = [r for r in rs if not r.failed]
        right = sum(r.found == r.expected for r in ok if r.expected is not None)
        wrong = sum(r.found is not None and r.found != r.expected for r in ok)
        times = [r.seconds for r in ok] or [float("nan")]
        cpu = [r.cpu_seconds for r in ok] or [float("nan")]
        cells = [
            scenario,
            case,
            str(len(rs)),
            str(len(rs) - len(ok)),
            _pct(sum(r.by_scale for r in ok), len(ok)),
            _pct(sum(r.by_noise for r in ok), len(ok)),
            "-" if rs[0].expected is None else _pct(right, len(ok)),
            _pct(wrong, len(ok)),
            f"{np.median(times):.2f} ({np.median(cpu):.2f})",
            f"{max(times):.2f} ({max(cpu):.2f})",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--no-clean-clock",
        action="store_true",
        help="skip the clean recordings with timestamps (the slowest clean case)",
    )
    args = ap.parse_args(argv)
    rows: list[Row] = []
    for k in range(args.trials):
        t0 = time.perf_counter()
        rows += trial(args.seed, k, not args.no_clean_clock)
        print(f"  trial {k}: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    misses = [r for r in rows if not r.failed and r.found != r.expected]
    for r in misses:
        print(f"  {r.scenario} / {r.case} (n={r.n}): found {r.found}", file=sys.stderr)
    sys.stderr.flush()
    print(
        f"{args.trials} trials, seed {args.seed}; joint {JOINT_RANGE[0]}-{JOINT_RANGE[1]} m, "
        f"{FRAMES[0]}-{FRAMES[1]} frames, noise {ROT_NOISE_DEG[0]}-{ROT_NOISE_DEG[1]} deg / "
        f"{1e3 * TRANS_NOISE[0]:.0f}-{1e3 * TRANS_NOISE[1]:.0f} mm per axis.\n"
    )
    print(render(rows), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
