"""The rig's bundle adjustment over several recordings (issue 19): a chain calibrated from
two trials, against each joint bundled from its own trial alone.

A chain cam0 -ball ``hip``- cam1 -hinge ``knee``- cam2 of board cameras
(:func:`sample_data_gen.rig_sim.rig_corner_recording`: 0.2 px corner noise, PnP poses from
intrinsics 0.3% off) is recorded once; its first half is the ``hip`` trial (cam2 not
recorded), its second half the ``knee`` trial (cam0 not recorded), each with its own
boards. Per trial:

- ``two recordings``: one :func:`acs_cli.core.rig_solve.estimate_rig` and one
  :func:`acs_cli.core.rig_bundle.bundle_adjust_rig` over both recordings (the hip trial's
  first common frame the reference);
- ``alone``: each joint's two-body rig (cam0-cam1 on the hip trial, cam1-cam2 on the knee
  trial), solved and bundled on its own frames.

Printed (Markdown): RMS over the trials of each joint's error in each camera (mm), of each
camera's focal length (px), and the RMS of error / reported std (1 for honest stds).

    .venv/bin/python benchmarks/bench_rig_bundle_recordings.py --trials 10
"""

# ruff: noqa: E402  (BLAS threads must be set before numpy is imported)
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import dataclasses
from collections import defaultdict
from collections.abc import Sequence

import numpy as np

from acs_cli.core.rig import rig_topology
from acs_cli.core.rig_bundle import bundle_adjust_rig
from acs_cli.core.rig_solve import estimate_rig
from sample_data_gen.rig_sim import rig_corner_recording

JOINTS = (("hip", ("cam0", "cam1"), "ball"), ("knee", ("cam1", "cam2"), "hinge"))


def trial(seed: int, n: int) -> dict[str, dict[str, tuple[float, float]]]:
    """``{method: {quantity: (error, std)}}`` of one simulated chain."""
    rec = rig_corner_recording(np.random.default_rng(seed), n, joints=JOINTS)
    topo = rec.rig.topology
    tracks, views, recs, common, ref = rec.two_trials("cam0", "cam2")
    of = recs.of_frame
    out: dict[str, dict[str, tuple[float, float]]] = {"two recordings": {}, "alone": {}}

    def record(method: str, name: str, ba: object, cams: tuple[str, str]) -> None:
        e = ba.estimate.edges[name]  # type: ignore[attr-defined]
        truth = rec.rig.edges[name]
        for c, o in zip(cams, (truth.o_p, truth.o_q), strict=True):
            err = float(np.linalg.norm(e.position_in[c] - o))
            out[method][f"{name} in {c} (mm)"] = (
                1e3 * err,
                1e3 * float(np.sqrt(np.trace(e.position_cov_in[c]))),
            )
        for c in cams:
            d = float(ba.intrinsics[c][0] - rec.intrinsics[c][0])  # type: ignore[attr-defined]
            key = f"fx {c} ({name} trial)" if method == "alone" else f"fx {c}"
            out[method][key] = (abs(d), float(ba.intrinsics_std[c][0]))  # type: ignore[attr-defined]

    est = estimate_rig(topo, tracks, reference_frame=ref, recordings=recs)
    ba = bundle_adjust_rig(topo, views, est, np.flatnonzero(common))
    for name, cams, _ in JOINTS:
        record("two recordings", name, ba, cams)
    for r, (name, cams, jtype) in enumerate(JOINTS):
        half = np.flatnonzero(common & (of == r))
        sub = rig_topology(cams, [(name, cams, jtype)], cams[0])
        t = {
            c: dataclasses.replace(
                tracks[c], T_w_c=tracks[c].T_w_c[half], valid=tracks[c].valid[half]
            )
            for c in cams
        }
        v = {
            c: dataclasses.replace(
                views[c], corners=views[c].corners[half], valid=views[c].valid[half]
            )
            for c in cams
        }
        e1 = estimate_rig(sub, t, reference_frame=0)
        record("alone", name, bundle_adjust_rig(sub, v, e1, np.arange(half.size)), cams)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--frames", type=int, default=240, help="simulated frames per trial")
    args = ap.parse_args(argv)
    got: dict[str, dict[str, list[tuple[float, float]]]] = defaultdict(lambda: defaultdict(list))
    for seed in range(args.trials):
        for method, q in trial(seed, args.frames).items():
            for k, v in q.items():
                got[method][k].append(v)
    print(f"{args.trials} trials, {args.frames} frames each (half per recording)\n")
    print("| quantity | two recordings: RMS error | err/std | alone: RMS error | err/std |")
    print("|---|---|---|---|---|")
    two, alone = got["two recordings"], got["alone"]
    for k in two:
        a = np.array(two[k])
        other = [v for kk, v in alone.items() if kk == k or kk.startswith(k + " (")]
        cells = [
            f"{np.sqrt(np.mean(a[:, 0] ** 2)):.3f}",
            f"{np.sqrt(np.mean((a[:, 0] / a[:, 1]) ** 2)):.2f}",
        ]
        for o in other:
            b = np.array(o)
            cells += [
                f"{np.sqrt(np.mean(b[:, 0] ** 2)):.3f}",
                f"{np.sqrt(np.mean((b[:, 0] / b[:, 1]) ** 2)):.2f}",
            ]
        print(f"| {k} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
