"""The rig's bundle adjustment on its corners (issue 9): accuracy against the pose-based rig
solve, calibration of its standard deviations, and time.

A rig of four board cameras (:data:`JOINTS`: cam0 -ball- cam1 -hinge- cam2, cam0 -rigid-
cam3) is simulated by :func:`sample_data_gen.rig_sim.rig_corner_recording`: each camera sees
its own 9x6 board (0.15 m squares) about 2 m ahead, corners with 0.2 px noise, PnP poses from
intrinsics 0.3% off in focal length (1 px in the centre, 5% in distortion), as a separate
intrinsics session would leave them. Per trial:

- pose-based: :func:`acs_cli.core.rig_solve.estimate_rig` on the PnP poses;
- bundle: :func:`acs_cli.core.rig_bundle.bundle_adjust_rig` from there, on every frame where
  all four cameras see their boards.

Printed (Markdown, stdout): RMS errors over the trials of every camera's ``T_cam_ref``
(rotation, translation), the joints, the hinge axis and the focal lengths, and per frame
adjusted, of the trajectories the rig writes (every camera's pose and every joint's point in
the reference camera's frame at the reference instant); the RMS of the
error divided by the reported standard deviation, per component (1 for an honest std); and the
bundle's time against frames.

    .venv/bin/python benchmarks/bench_rig_bundle.py              # 20 trials (~3 min here)
    .venv/bin/python benchmarks/bench_rig_bundle.py --trials 3   # a smoke run
    .venv/bin/python benchmarks/bench_rig_bundle.py --no-timing  # the accuracy table only
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
from acs_cli.core.rig_bundle import bundle_adjust_rig
from acs_cli.core.rig_solve import RigEstimate, estimate_rig
from acs_cli.errors import DegenerateMotionError
from sample_data_gen.rig_sim import CornerRecording, rig_corner_recording

JOINTS = (
    ("j01", ("cam0", "cam1"), "ball"),
    ("j12", ("cam1", "cam2"), "hinge"),
    ("r03", ("cam0", "cam3"), "rigid"),
)


def _solve(rec: CornerRecording, frames: np.ndarray | None = None) -> tuple:
    common = rec.common
    ref = int(np.flatnonzero(common)[0])
    est = estimate_rig(rec.rig.topology, rec.tracks(), reference_frame=ref)
    views = rec.views()
    use = np.flatnonzero(common) if frames is None else frames
    t0 = time.perf_counter()
    ba = bundle_adjust_rig(rec.rig.topology, views, est, use)
    return est, ba, ref, time.perf_counter() - t0


def _errors(rec: CornerRecording, est: RigEstimate, ref: int) -> dict[str, tuple]:
    """Per quantity: (error vector, std vector or None)."""
    out: dict[str, tuple] = {}
    truth = rec.rig.T_cam_ref(ref)
    for c, e in est.cameras.items():
        if c == rec.rig.topology.reference:
            continue
        T = e.T_cam_ref
        dr = se3.rotvec_from_matrix(truth[c][:3, :3].T @ T[:3, :3])  # right perturbation
        out[f"{c} T_cam_ref rot (deg)"] = (np.degrees(dr), e.rotation_std_deg)
        out[f"{c} T_cam_ref trans (mm)"] = (1e3 * (T[:3, 3] - truth[c][:3, 3]),
                                            1e3 * e.translation_std)  # fmt: skip
    for name, e in est.edges.items():
        tr = rec.rig.edges[name]
        if e.joint.type == "rigid":
            continue
        p, q = e.joint.between
        for c, o in ((p, tr.o_p), (q, tr.o_q)):
            std = 1e3 * np.sqrt(np.maximum(np.diag(e.position_cov_in[c]), 0))
            out[f"{name} position in {c} (mm)"] = (1e3 * (e.position_in[c] - o), std)
        if e.joint.type == "hinge":
            u = e.axis_in[p] * np.sign(e.axis_in[p] @ tr.axis_p)
            ang = np.degrees(np.arccos(min(abs(float(u @ tr.axis_p)), 1.0)))
            out[f"{name} axis in {p} (deg)"] = (np.array([ang]), None)
    return out


def _trajectory_errors(
    rec: CornerRecording, est: RigEstimate, ref: int, frames: np.ndarray
) -> dict[str, np.ndarray]:
    """Per-frame errors of the trajectories the rig writes (``write_rig_trajectories``:
    every body's and ball or hinge joint's pose in the reference camera's frame at the
    reference instant) over ``frames``: rotation (deg) and translation (mm) of every camera,
    and the distance (mm) of every joint's point."""
    topo = rec.rig.topology
    r = topo.reference
    T_ref_w = se3.invert_transforms(est.cameras[r].poses_in_reference_world[ref])
    T_true = se3.invert_transforms(rec.rig.T_W_c[r][ref])
    got = {c: T_ref_w @ e.poses_in_reference_world[frames] for c, e in est.cameras.items()}
    truth = {c: T_true @ rec.rig.T_W_c[c][frames] for c in est.cameras}
    rot, trans, joint = [], [], []
    for c in est.cameras:
        d = np.swapaxes(truth[c][:, :3, :3], 1, 2) @ got[c][:, :3, :3]
        rot.append(np.degrees(np.linalg.norm(se3.rotvec_from_matrix(d), axis=1)))
        trans.append(1e3 * np.linalg.norm(got[c][:, :3, 3] - truth[c][:, :3, 3], axis=1))
    for name, e in est.edges.items():
        if not e.position_in:
            continue
        p = e.joint.between[0]
        o = se3.transform_points(got[p], e.position_in[p])
        o_true = se3.transform_points(truth[p], rec.rig.edges[name].o_p)
        joint.append(1e3 * np.linalg.norm(o - o_true, axis=1))
    return {
        "trajectories, every camera: rot (deg)": np.concatenate(rot),
        "trajectories, every camera: trans (mm)": np.concatenate(trans),
        "trajectories, ball and hinge joints' points (mm)": np.concatenate(joint),
    }


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--frames", type=int, default=150, help="simulated frames per trial")
    ap.add_argument("--no-timing", action="store_true", help="skip the time table")
    args = ap.parse_args(argv)
    pose: dict[str, list] = defaultdict(list)
    bundle: dict[str, list] = defaultdict(list)
    focal: dict[str, list] = defaultdict(list)
    traj_pose: dict[str, list] = defaultdict(list)
    traj_bundle: dict[str, list] = defaultdict(list)
    times, used, skipped = [], [], 0
    for seed in range(args.trials):
        rec = rig_corner_recording(np.random.default_rng(1000 + seed), args.frames, joints=JOINTS)
        try:
            est, ba, ref, sec = _solve(rec)
        except DegenerateMotionError as exc:  # the pose-based solve refuses a weak motion
            skipped += 1
            print(f"seed {seed}: skipped ({exc})", file=sys.stderr)
            continue
        times.append(sec)
        used.append(ba.frames.size)
        for k, v in _errors(rec, est, ref).items():
            pose[k].append(v)
        for k, v in _errors(rec, ba.estimate, ref).items():
            bundle[k].append(v)
        for k, v in _trajectory_errors(rec, est, ref, ba.frames).items():
            traj_pose[k].append(v)
        for k, v in _trajectory_errors(rec, ba.estimate, ref, ba.frames).items():
            traj_bundle[k].append(v)
        for c in rec.rig.topology.cameras:
            focal["initial"].append(rec.intrinsics0[c][0] - rec.intrinsics[c][0])
            focal["bundle"].append(ba.intrinsics[c][0] - rec.intrinsics[c][0])
            focal["z"].append((ba.intrinsics[c][0] - rec.intrinsics[c][0])
                              / ba.intrinsics_std[c][0])  # fmt: skip
        print(f"seed {seed}: {ba.frames.size} frames, {sec:.2f} s", file=sys.stderr)
    n = len(times)
    print(f"{n} trials ({skipped} refused by the pose-based solve), {int(np.mean(used))} "
          "frames on average (every camera seeing its board), 4 cameras, 0.2 px corner "
          "noise\n")  # fmt: skip
    print("| quantity | RMS pose-based | RMS bundle | bundle / pose | RMS error/std pose-based "
          "| RMS error/std bundle |")  # fmt: skip
    print("|---|---|---|---|---|---|")

    def rms(rows: list, norm: bool) -> float:
        if norm:
            if rows[0][1] is None:
                return float("nan")
            z = np.concatenate([e / np.maximum(s, 1e-300) for e, s in rows])
            return float(np.sqrt(np.mean(z**2)))
        return float(np.sqrt(np.mean([np.sum(e**2) for e, _ in rows])))

    for k in bundle:
        a, b = rms(pose[k], False), rms(bundle[k], False)
        za, zb = rms(pose[k], True), rms(bundle[k], True)
        print(f"| {k} | {a:.3f} | {b:.3f} | {b / a:.2f} | {za:.2f} | {zb:.2f} |")
    fi = np.sqrt(np.mean(np.square(focal["initial"])))
    fb = np.sqrt(np.mean(np.square(focal["bundle"])))
    fz = np.sqrt(np.mean(np.square(focal["z"])))
    print(f"| fx (px), 4 cameras | {fi:.3f} (initial) | {fb:.3f} | {fb / fi:.2f} | — | {fz:.2f} |")
    for k in traj_bundle:
        a = float(np.sqrt(np.mean(np.square(np.concatenate(traj_pose[k])))))
        b = float(np.sqrt(np.mean(np.square(np.concatenate(traj_bundle[k])))))
        print(f"| {k}, per frame | {a:.3f} | {b:.3f} | {b / a:.2f} | — | — |")
    if args.no_timing:
        return 0
    print("\nTime of `bundle_adjust_rig` (4 cameras, seconds, one run each):\n")
    print("| frames | seconds |\n|---|---|")
    rec = rig_corner_recording(np.random.default_rng(1000), 400, joints=JOINTS)
    common = np.flatnonzero(rec.common)
    for m in (25, 50, 100, 200):
        if m > common.size:
            break
        frames = common[:m]
        _e, ba, _r, sec = _solve(rec, frames)
        print(f"| {frames.size} | {sec:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
