"""Time offset between two cameras' clocks (issue 10): accuracy of ``dt`` and its cost to
the calibration.

Per trial a random rig (``make_rig``: joint 1-2 m from each camera) moves smoothly
(:func:`sample_data_gen.acs_sim.smooth_general_sequence`, sums of sinusoids) for 300 frames
at 30 Hz, with pose noise 0.1 deg / 5 mm per axis. Three runs of the self-calibrated refined
estimator (``estimate_relpose``), on

- sync: synchronised clocks, paired by timestamp;
- offset, estimated: camera B's clock 37 ms ahead (``--offset``), ``estimate_time_offset``
  (+-0.2 s) then the calibration on the pairing at the estimate (as ``acscal relpose
  --estimate-time-offset``);
- offset, ignored: the same recording paired by timestamp, as if synchronised.

Printed (Markdown): the offset's mean, RMS and largest error over trials, the RMS of error /
reported std, and the RMS errors of the joint (in A and B) and of ``T_b_a`` (rotation,
translation) in each case.

    .venv/bin/python benchmarks/bench_time_offset.py               # 30 trials, ~3 min here
    .venv/bin/python benchmarks/bench_time_offset.py --offset 0.025  # 0.75 frame ahead
    .venv/bin/python benchmarks/bench_time_offset.py --trials 3    # a smoke run
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
from collections.abc import Sequence

import numpy as np

from acs_cli.core import se3
from acs_cli.core.relpose import RelposeEstimate, estimate_relpose
from acs_cli.core.time_offset import PoseInterpolator, estimate_time_offset
from sample_data_gen.acs_sim import add_pose_noise, make_rig, smooth_general_sequence

OFFSET = 0.037


def _fit(Ta: np.ndarray, Tb: np.ndarray) -> np.ndarray:
    return estimate_relpose(Ta, Tb, reject_outliers=False).residuals


def _errors(est: RelposeEstimate, rig, T_b_a: np.ndarray) -> dict[str, float]:
    d = T_b_a[:3, :3].T @ est.T_b_a[:3, :3]
    return {
        "joint in A (mm)": 1e3 * float(np.linalg.norm(est.position_in_a - rig.o_a)),
        "joint in B (mm)": 1e3 * float(np.linalg.norm(est.position_in_b - rig.o_b)),
        "T_b_a rotation (deg)": float(se3.rotation_angle_deg(d)),
        "T_b_a translation (mm)": 1e3 * float(np.linalg.norm(est.T_b_a[:3, 3] - T_b_a[:3, 3])),
    }


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=30)
    ap.add_argument("--offset", type=float, default=OFFSET, help="B's clock ahead (seconds)")
    args = ap.parse_args(argv)
    offset = args.offset
    errs: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    dts, zs, secs = [], [], []
    for seed in range(args.trials):
        rng = np.random.default_rng(500 + seed)
        rig = make_rig(rng)
        state = rng.bit_generator.state
        sync = smooth_general_sequence(rng, rig, 300)
        rng.bit_generator.state = state  # the same motion, B's clock ahead
        late = smooth_general_sequence(rng, rig, 300, time_offset_s=offset)
        noise = np.random.default_rng(900 + seed)
        a = add_pose_noise(noise, sync.T_wa_a, 0.1, 0.005)
        b_sync = add_pose_noise(noise, sync.T_wb_b, 0.1, 0.005)
        noise = np.random.default_rng(900 + seed)
        a2 = add_pose_noise(noise, late.T_wa_a, 0.1, 0.005)
        b_late = add_pose_noise(noise, late.T_wb_b, 0.1, 0.005)
        t = sync.timestamps
        truth = sync.T_b_a(0)
        for k, v in _errors(estimate_relpose(a, b_sync), rig, truth).items():
            errs["sync"][k].append(v)
        t0 = time.perf_counter()
        off = estimate_time_offset(t, a2, t, b_late, _fit, 0.2)
        idx = np.flatnonzero(off.frames)
        interp = PoseInterpolator(t, b_late)
        tb = t[idx] + off.offset_s
        keep = interp.valid(tb)
        est = estimate_relpose(a2[idx[keep]], interp(tb[keep]))
        secs.append(time.perf_counter() - t0)
        truth_k = late.T_b_a(int(idx[keep][0]))
        for k, v in _errors(est, rig, truth_k).items():
            errs["offset, estimated"][k].append(v)
        for k, v in _errors(estimate_relpose(a2, b_late), rig, late.T_b_a(0)).items():
            errs["offset, ignored"][k].append(v)
        dts.append(off.offset_s - offset)
        zs.append((off.offset_s - offset) / off.std_s)
        print(f"seed {seed}: dt {1e3 * off.offset_s:.3f} ms +- {1e3 * off.std_s:.3f}, "
              f"{secs[-1]:.1f} s", file=sys.stderr)  # fmt: skip
    dts_a, zs_a = np.asarray(dts), np.asarray(zs)
    print(f"{len(dts)} trials, 300 frames at 30 Hz, true offset {1e3 * offset:g} ms, pose "
          "noise 0.1 deg / 5 mm per axis\n")  # fmt: skip
    print("| offset | value |\n|---|---|")
    print(f"| mean error (ms) | {1e3 * np.mean(dts_a):+.3f} |")
    print(f"| RMS error (ms) | {1e3 * np.sqrt(np.mean(dts_a**2)):.3f} |")
    print(f"| largest error (ms) | {1e3 * np.max(np.abs(dts_a)):.3f} |")
    print(f"| RMS error / reported std | {np.sqrt(np.mean(zs_a**2)):.2f} |")
    print(f"| seconds (search and calibration), median | {np.median(secs):.1f} |")
    print("\n| quantity | sync | offset, estimated | estimated / sync | offset, ignored |")
    print("|---|---|---|---|---|")
    for k in errs["sync"]:
        r = {c: float(np.sqrt(np.mean(np.square(errs[c][k])))) for c in errs}
        est, ign = r["offset, estimated"], r["offset, ignored"]
        print(f"| {k} | {r['sync']:.3f} | {est:.3f} | {est / r['sync']:.2f} | {ign:.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
