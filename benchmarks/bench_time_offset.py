"""Time offset between cameras' clocks (issues 10 and 19): accuracy of ``dt`` and its cost to
the calibration, for the pair command and for a rig, with confidence intervals.

Pair (default). Per trial a random rig (``make_rig``: joint 1-2 m from each camera) moves
smoothly (:func:`sample_data_gen.acs_sim.smooth_general_sequence`, sums of sinusoids) for
300 frames at 30 Hz, with pose noise 0.1 deg / 5 mm per axis. The self-calibrated refined
estimator (``estimate_relpose``) on

- sync: synchronised clocks, paired by timestamp, every frame (reference frame 0);
- sync, same frames: the same, on the frames the offset run pairs (reference: its first);
- known offset: camera B's clock 37 ms ahead (``--offset``), B interpolated (SE(3) splines)
  at A's times plus the *true* offset, on those frames: the interpolation alone;
- estimated: ``estimate_time_offset`` (+-0.2 s) then the calibration on B interpolated at
  the estimate (as ``acscal relpose --estimate-time-offset``);
- ignored: the offset recording paired by timestamp, as if synchronised.

The synchronised and offset recordings share the motion and the noise draws, so the ratios
are paired; their 95% intervals are percentile bootstraps over trials.

Rig (``--rig``). :func:`sample_data_gen.rig_sim.rig_recording` (smooth, 300 frames at
30 Hz, 0.1 deg / 5 mm), cam0 -(ball j01)- cam1, cam0 -(rigid r02)- cam2, cam1's clock 37 ms
and cam2's 19 ms ahead of cam0's; :func:`acs_cli.core.rig_solve.estimate_rig` on the tracks of
``run_rig``'s branches: sync (``tracks_on_timeline``), known offset and estimated
(``tracks_with_offsets``, the latter with ``rig_time_offsets``, ``max_offset`` 0.1 s). Every
track starts at frame 0, so all runs report ``T_cam_ref`` at the same instant (frame 0, or
``--reference-frame``). ``--known-only`` skips the offset's search and its run (about 1 s a
trial instead of 30): the interpolation's cost alone, over many trials.

    .venv/bin/python benchmarks/bench_time_offset.py --trials 40        # ~4 min, loaded
    .venv/bin/python benchmarks/bench_time_offset.py --rig --trials 40  # ~25 min, loaded
    .venv/bin/python benchmarks/bench_time_offset.py --trials 3         # a smoke run
    .venv/bin/python benchmarks/bench_time_offset.py --rig --known-only --trials 200
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
from pathlib import Path

import numpy as np

from acs_cli.core import se3
from acs_cli.core.relpose import RelposeEstimate, estimate_relpose
from acs_cli.core.time_offset import PoseInterpolator, estimate_time_offset
from sample_data_gen.acs_sim import add_pose_noise, make_rig, smooth_general_sequence

OFFSET = 0.037
#: The rig's clock offsets to cam0 (seconds).
RIG_OFFSETS = {"cam1": 0.037, "cam2": 0.019}
RIG_JOINTS = (("j01", ("cam0", "cam1"), "ball"), ("r02", ("cam0", "cam2"), "rigid"))
#: Columns: the ratios are to these runs.
BASES = ("sync, same frames", "known offset")

Errors = dict[str, dict[str, list[float]]]


def _fit(Ta: np.ndarray, Tb: np.ndarray) -> np.ndarray:
    return estimate_relpose(Ta, Tb, reject_outliers=False).residuals


def _pair_errors(est: RelposeEstimate, rig, T_b_a: np.ndarray) -> dict[str, float]:
    d = T_b_a[:3, :3].T @ est.T_b_a[:3, :3]
    return {
        "joint in A (mm)": 1e3 * float(np.linalg.norm(est.position_in_a - rig.o_a)),
        "joint in B (mm)": 1e3 * float(np.linalg.norm(est.position_in_b - rig.o_b)),
        "T_b_a rotation (deg)": float(se3.rotation_angle_deg(d)),
        "T_b_a translation (mm)": 1e3 * float(np.linalg.norm(est.T_b_a[:3, 3] - T_b_a[:3, 3])),
    }


def pair_trial(seed: int, offset: float, errs: Errors) -> tuple[float, float]:
    """One recording; appends each run's errors, returns the offset's error and std (s)."""
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
    off = estimate_time_offset(t, a2, t, b_late, _fit, 0.2)
    idx = np.flatnonzero(off.frames)
    interp = PoseInterpolator(t, b_late)
    tb = t[idx] + off.offset_s
    keep = interp.valid(tb)
    idx, tb = idx[keep], tb[keep]
    truth = sync.T_b_a(int(idx[0]))  # T_b_a at A's times: the same in both recordings
    runs = {
        "sync": (estimate_relpose(a, b_sync), sync.T_b_a(0)),
        "sync, same frames": (estimate_relpose(a[idx], b_sync[idx]), truth),
        "known offset": (estimate_relpose(a2[idx], interp(t[idx] + offset)), truth),
        "estimated": (estimate_relpose(a2[idx], interp(tb)), truth),
        "ignored": (estimate_relpose(a2, b_late), late.T_b_a(0)),
    }
    for run, (est, T) in runs.items():
        for k, v in _pair_errors(est, rig, T).items():
            errs[run][k].append(v)
    return off.offset_s - offset, off.std_s


def rig_trial(
    seed: int, errs: Errors, known_only: bool = False, k: int = 0
) -> dict[str, tuple[float, float]]:
    """One rig recording; appends each run's errors (``T_cam_ref`` at frame ``k``), returns
    each camera's offset error and std (s), or nothing with ``known_only``."""
    import yaml

    from acs_cli.core.rig_solve import estimate_rig
    from acs_cli.io.trajectory import Trajectory
    from acs_cli.stages import rig as stage
    from sample_data_gen.rig_sim import rig_recording

    text = (
        "schema_version: 2\noutput: out\ncameras:\n"
        + "".join(f"  {c}: {{poses: {c}.tum}}\n" for c in ("cam0", "cam1", "cam2"))
        + "joints:\n  j01: {between: [cam0, cam1], type: ball}\n"
        "  r02: {between: [cam0, cam2], type: rigid}\n"
        "estimate_time_offset: true\nmax_offset: 0.1\n"
    )
    config = stage.parse_rig_config(yaml.safe_load(text), Path("rig.yaml"))

    def recording(offsets: dict[str, float]):
        return rig_recording(
            np.random.default_rng(seed), 300, joints=RIG_JOINTS, smooth=True,
            time_offsets=offsets, sigma_rot_deg=0.1, sigma_trans=0.005,
            max_rotation_deg=60.0, max_articulation_deg=40.0, translation_range=1.0,
        )  # fmt: skip

    sync, late = recording({}), recording(RIG_OFFSETS)

    def trajectories(rec) -> dict[str, Trajectory]:
        return {c: Trajectory(rec.timestamps, T, f"{c}.tum", "tum", True) for c, T in
                rec.T_wc_c.items()}  # fmt: skip

    def record(run: str, tracks) -> None:
        est = estimate_rig(config.topology, tracks, reference_frame=k)
        e, o = est.edges["j01"], sync.edges["j01"]
        for c, o_c in (("cam0", o.o_p), ("cam1", o.o_q)):
            err = 1e3 * float(np.linalg.norm(e.position_in[c] - o_c))
            errs[run][f"j01 in {c} (mm)"].append(err)
        truth = sync.T_cam_ref(k)
        for c in ("cam1", "cam2"):
            T = est.cameras[c].T_cam_ref
            if T is None:
                raise RuntimeError(f"{c}: no T_cam_ref")
            d = truth[c][:3, :3].T @ T[:3, :3]
            errs[run][f"{c} T_cam_ref rotation (deg)"].append(float(se3.rotation_angle_deg(d)))
            errs[run][f"{c} T_cam_ref translation (mm)"].append(
                1e3 * float(np.linalg.norm(T[:3, 3] - truth[c][:3, 3]))
            )

    tracks, _, _, _ = stage.tracks_on_timeline(config, trajectories(sync))
    record("sync", tracks)
    late_traj = trajectories(late)
    known = {"cam0": (0.0, 0.0)} | {c: (v, 0.0) for c, v in RIG_OFFSETS.items()}
    offsets = {} if known_only else stage.rig_time_offsets(config, late_traj, {})[0]
    runs = [("known offset", known)] + ([] if known_only else [("estimated", offsets)])
    for run, given in runs:
        tracks, slots, _ = stage.tracks_with_offsets(config, late_traj, given)
        if slots[0] != late.timestamps[0]:  # T_cam_ref at another instant than sync's
            raise RuntimeError(f"seed {seed}: the {run} timeline starts at {slots[0]} s")
        record(run, tracks)
    n = tracks["cam0"].T_w_c.shape[0]  # the timeline starts at frame 0 and ends earlier
    same = {c: Trajectory(t.timestamps[:n], t.T_world_cam[:n], t.source, "tum", True) for c, t
            in trajectories(sync).items()}  # fmt: skip
    record("sync, same frames", stage.tracks_on_timeline(config, same)[0])
    return {c: (offsets[c][0] - v, offsets[c][1]) for c, v in RIG_OFFSETS.items() if offsets}


def _rms(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=-1))


def print_tables(errs: Errors) -> None:
    """RMS errors of every run, and their ratios to :data:`BASES` with 95% intervals."""
    runs = list(errs)
    quantities = list(errs[runs[0]])
    n = len(errs[runs[0]][quantities[0]])
    boot = np.random.default_rng(0).integers(n, size=(4000, n))
    print("| RMS error | " + " | ".join(runs) + " |")
    print("|---" * (len(runs) + 1) + "|")
    for q in quantities:
        print(f"| {q} | " + " | ".join(f"{_rms(np.array(errs[r][q])):.3f}" for r in runs) + " |")
    for base in BASES:
        others = [r for r in runs if r != base]
        print(f"\nRatio of RMS errors to '{base}' (95% paired bootstrap interval):\n")
        print("| quantity | " + " | ".join(others) + " |")
        print("|---" * (len(others) + 1) + "|")
        for q in quantities:
            b = np.array(errs[base][q])
            cells = []
            for r in others:
                x = np.array(errs[r][q])
                lo, hi = np.percentile(_rms(x[boot]) / _rms(b[boot]), [2.5, 97.5])
                cells.append(f"{_rms(x) / _rms(b):.2f} ({lo:.2f}-{hi:.2f})")
            print(f"| {q} | " + " | ".join(cells) + " |")


def _offset_rows(name: str, err: np.ndarray, std: np.ndarray) -> None:
    print(f"| {name}: mean error (ms) | {1e3 * np.mean(err):+.3f} |")
    print(f"| {name}: RMS error (ms) | {1e3 * _rms(err):.3f} |")
    print(f"| {name}: largest error (ms) | {1e3 * np.max(np.abs(err)):.3f} |")
    print(f"| {name}: RMS error / reported std | {_rms(err / std):.2f} |")


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=40)
    ap.add_argument("--offset", type=float, default=OFFSET, help="B's clock ahead (seconds)")
    ap.add_argument("--rig", action="store_true", help="the rig (three cameras) instead")
    ap.add_argument(
        "--known-only",
        action="store_true",
        help="rig: no offset search, the known offset's runs only",
    )
    ap.add_argument("--reference-frame", type=int, default=0, help="rig: T_cam_ref's frame")
    args = ap.parse_args(argv)
    errs: Errors = defaultdict(lambda: defaultdict(list))
    offs: dict[str, list[tuple[float, float]]] = defaultdict(list)
    secs = []
    for seed in range(args.trials):
        t0 = time.perf_counter()
        if args.rig:
            for c, got in rig_trial(seed, errs, args.known_only, args.reference_frame).items():
                offs[c].append(got)
        else:
            offs["B"].append(pair_trial(seed, args.offset, errs))
        secs.append(time.perf_counter() - t0)
        print(f"seed {seed}: " + ", ".join(f"{c} dt error {1e3 * v[-1][0]:+.3f} ms +- "
              f"{1e3 * v[-1][1]:.3f}" for c, v in offs.items()) + f", {secs[-1]:.1f} s",
              file=sys.stderr)  # fmt: skip
    what = (
        f"rig, cam1 {1e3 * RIG_OFFSETS['cam1']:g} ms and cam2 {1e3 * RIG_OFFSETS['cam2']:g} ms "
        f"ahead of cam0, T_cam_ref at frame {args.reference_frame}"
        + (", known offset only" if args.known_only else "")
        if args.rig
        else f"pair, true offset {1e3 * args.offset:g} ms"
    )
    print(f"{args.trials} trials, 300 frames at 30 Hz, {what}, pose noise 0.1 deg / 5 mm per "
          "axis\n")  # fmt: skip
    print("| offset | value |\n|---|---|")
    for c, v in offs.items():
        a = np.asarray(v)
        _offset_rows(c, a[:, 0], a[:, 1])
    print(f"| seconds per trial (all runs), median | {np.median(secs):.1f} |\n")
    print_tables(errs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
