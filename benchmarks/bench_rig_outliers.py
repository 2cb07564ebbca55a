"""The rig's outlier test (issue 19: one test with the two-camera estimators).

Clean rigs: how many frames the test rejects (it should reject almost none, at any number of
frames). Rigs with 10% gross outliers on one camera (translations off by 0.3 m per axis):
the ball joint's error and how many frames were rejected.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_rig_outliers.py [--seeds 20]
"""

from __future__ import annotations

import argparse

import numpy as np

from acs_cli.core.rig_solve import CameraTrack, estimate_rig
from acs_cli.errors import AcsError
from sample_data_gen.rig_sim import rig_recording


def _tracks(T: dict[str, np.ndarray], unknown: dict[str, bool]) -> dict[str, CameraTrack]:
    n = next(iter(T.values())).shape[0]
    return {c: CameraTrack(X, np.ones(n, bool), unknown[c]) for c, X in T.items()}


def clean(seeds: int, frames: int) -> tuple[int, int, int]:
    """Frames rejected, frames in all, recordings refused."""
    rejected = total = refused = 0
    for seed in range(seeds):
        rec = rig_recording(np.random.default_rng(seed), frames, sigma_rot_deg=0.5,
                            sigma_trans=0.01)  # fmt: skip
        try:
            est = estimate_rig(rec.topology, _tracks(rec.T_wc_c, rec.unknown_scale))
        except AcsError:
            refused += 1
            continue
        rejected += sum(e.frames_rejected for e in est.edges.values())
        total += sum(e.frames_used + e.frames_rejected for e in est.edges.values())
    return rejected, total, refused


def gross(seeds: int, frames: int) -> tuple[float, float, float, int]:
    """The ball joint j02's median and RMS error (mm), the mean number of frames rejected on
    it, and the recordings refused."""
    errors, rejected, refused = [], [], 0
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        rec = rig_recording(rng, frames, sigma_rot_deg=0.5, sigma_trans=0.01)
        T = dict(rec.T_wc_c)
        bad = rng.choice(np.arange(1, frames), size=max(1, frames // 10), replace=False)
        cam2 = T["cam2"].copy()
        cam2[bad, :3, 3] += rng.normal(scale=0.3, size=(bad.size, 3))
        T["cam2"] = cam2
        try:
            est = estimate_rig(rec.topology, _tracks(T, rec.unknown_scale))
        except AcsError:
            refused += 1
            continue
        e = est.edges["j02"]
        errors.append(float(np.linalg.norm(e.position_in["cam0"] - rec.edges["j02"].o_p)))
        rejected.append(e.frames_rejected)
    err = 1000 * np.asarray(errors)
    return float(np.median(err)), float(np.sqrt(np.mean(err**2))), float(np.mean(rejected)), refused


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args(argv)
    print("| frames | clean: frames rejected | recordings refused |")
    print("|---|---|---|")
    for n in (15, 30, 100):
        r, t, f = clean(args.seeds, n)
        print(f"| {n} | {r} of {t} | {f} |")
    print()
    print("| frames | j02 error median (mm) | RMS (mm) | rejected (of the bad) | refused |")
    print("|---|---|---|---|---|")
    for n in (20, 60):
        med, rms, rej, f = gross(args.seeds, n)
        print(f"| {n} | {med:.1f} | {rms:.1f} | {rej:.1f} (of {max(1, n // 10)}) | {f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
