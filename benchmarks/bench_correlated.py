"""Stds under errors correlated over time (issue 20, item 1): the model's covariance against
the block sandwich of :mod:`acs_cli.core.correlated`, on simulated motion capture.

Hip (ball) and knee (hinge) trials of :mod:`sample_data_gen.mocap_sim` (60 Hz, independent
pose noise 0.5 deg / 1 mm on both segments), solved by the rig engine with one shared world,
with three kinds of error on the moving segment:

- ``independent``: none beyond the independent noise (the stds must not change);
- ``drift``: a smooth random error in time (``--drift-mm``, and a fifth of it in degrees: a
  few sines of 0.15-0.8 Hz), as a tracker drifts or skin slides with muscle activity;
- ``slide``: a marker slide that is a fixed function of the flexion (``--slide-mm``), the
  simulator's skin-marker model.

Per kind and quantity: error/std RMS (``sqrt(mean(d' C^-1 d / k))``, k = 3 for a point, 2
for a hinge point or axis) with the model's covariance and with the block sandwich, and the
share of trials whose covariance grew. Real data: ``bench_mocap.py --skip-sim`` (halves,
blocks, left against right).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_correlated.py            # ~2 min here
    PYTHONPATH=. .venv/bin/python benchmarks/bench_correlated.py --seeds 50 --frames 1200
"""

# ruff: noqa: E402  (BLAS threads must be set before numpy is imported)
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

import acs_cli.core.rig_solve as rig_solve
from acs_cli.core import se3
from acs_cli.core.rig_solve import Recordings, estimate_rig
from sample_data_gen import mocap_sim as M

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_mocap as BM

KINDS = ("independent", "drift", "slide")


def _drift(rng: np.random.Generator, t: np.ndarray, mm: float) -> np.ndarray:
    """``(n, 4, 4)``: a smooth error in time, ``mm`` millimetres and ``mm / 5`` degrees RMS."""
    d = np.stack(
        [M._smooth(rng, t, np.radians(mm / 5.0)) for _ in range(3)]
        + [M._smooth(rng, t, mm / 1000.0) for _ in range(3)],
        axis=1,
    )
    return se3.transforms_from_rt(se3.matrix_from_rotvec(d[:, :3]), d[:, 3:])


def trial(
    kind: str, seed: int, frames: int, drift_mm: float, slide_mm: float
) -> tuple[M.MocapTrial, M.MocapTrial]:
    rng = np.random.default_rng([20, seed])
    slide = slide_mm if kind == "slide" else 0.0
    hip = M.hip_trial(rng, n=frames, slide_mm=slide)
    knee = M.knee_trial(rng, n=frames, slide_mm=slide)
    if kind == "drift":
        hip.measured["femur"] = hip.measured["femur"] @ _drift(rng, hip.times, drift_mm)
        knee.measured["tibia"] = knee.measured["tibia"] @ _drift(rng, knee.times, drift_mm)
    return hip, knee


def z2(est: object, which: str) -> tuple[float, bool]:
    """The squared normalised error (per dof) of one quantity and whether its rig grew."""
    grew = bool(est.correlated.detected)  # type: ignore[attr-defined]
    if which == "hip centre":
        e = est.edges["hip"]  # type: ignore[attr-defined]
        d = e.position_in["pelvis"] - M.HIP_IN_PELVIS
        return float(d @ np.linalg.solve(e.position_cov_in["pelvis"], d)) / 3, grew
    k = est.edges["knee"]  # type: ignore[attr-defined]
    if which == "knee axis":
        ang = np.degrees(np.arccos(min(1.0, abs(float(k.axis_in["femur"] @ BM._U)))))
        return float((ang / k.axis_std_deg_in["femur"]) ** 2), grew
    d = k.position_in["femur"] - BM.KNEE_POINT_IN_FEMUR
    return float(d @ np.linalg.pinv(k.position_cov_in["femur"]) @ d) / 2, grew


def run(
    args: argparse.Namespace, model_only: bool
) -> dict[tuple[str, str], list[tuple[float, bool]]]:
    real: Callable[..., object] = rig_solve.covariance_with_correlated_errors
    if model_only:
        rig_solve.covariance_with_correlated_errors = lambda cov, *a, **k: (  # type: ignore[assignment]
            cov,
            rig_solve.NOT_TESTED,
        )
    out: dict[tuple[str, str], list[tuple[float, bool]]] = {}
    try:
        for kind in KINDS:
            for s in range(args.seeds):
                hip, knee = trial(kind, s, args.frames, args.drift_mm, args.slide_mm)
                n = args.frames
                h = estimate_rig(
                    BM.HIP, BM.tracks_of(hip.measured), recordings=Recordings.single(n, True)
                )
                k = estimate_rig(
                    BM.KNEE, BM.tracks_of(knee.measured), recordings=Recordings.single(n, True)
                )
                out.setdefault((kind, "hip centre"), []).append(z2(h, "hip centre"))
                for q in ("knee axis", "knee point"):
                    out.setdefault((kind, q), []).append(z2(k, q))
    finally:
        rig_solve.covariance_with_correlated_errors = real  # type: ignore[assignment]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--drift-mm", type=float, default=5.0)
    ap.add_argument("--slide-mm", type=float, default=5.0)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    before = run(args, model_only=True)
    after = run(args, model_only=False)
    print(
        f"## Stds under correlated errors ({args.seeds} seeds, {args.frames} frames at 60 Hz, "
        f"drift {args.drift_mm} mm, slide {args.slide_mm} mm)\n"
    )
    print("| error | quantity | error/std RMS, model | error/std RMS, block sandwich | grown |")
    print("|---|---|---|---|---|")
    for key, rows in after.items():
        b = np.sqrt(np.mean([z for z, _ in before[key]]))
        a = np.sqrt(np.mean([z for z, _ in rows]))
        grown = np.mean([g for _, g in rows])
        print(f"| {key[0]} | {key[1]} | {b:.2f} | {a:.2f} | {100 * grown:.0f}% |")
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
