"""Rigs of many cameras (issue 9): solve time, accuracy against the two-camera commands, and
degenerate motion named edge by edge.

Three parts, each printing Markdown tables to stdout (progress on stderr):

1. Time of :func:`acs_cli.core.rig_solve.estimate_rig` against cameras x frames: rigs of 2,
   3, 4, 6 and 8 cameras in a tree mixing ball, hinge and rigid joints (:data:`TREE_JOINTS`),
   0.3 deg / 1 cm pose noise, one camera (cam1) with unknown scale. Seconds, best of
   ``--repeat`` (``time.perf_counter``); generating the data is not timed.
2. Accuracy over ``--trials`` seeded recordings: for every edge ``(p, q)`` of all-ball rigs (a
   chain and a star), the two-camera self-calibration (:func:`estimate_relpose` on the pair's
   tracks alone) against the rig solve: RMS error of the joint in ``p`` and ``q`` and of
   ``T_q_p`` at frame 0, and of every camera's ``T_cam_ref`` (pairs chained along the tree).
   Then a mixed rig (rigid, ball, hinge, rigid) that only the rig solve can calibrate.
3. A truck and its trailer on flat ground (a planar hinge): the DegenerateMotionError.

    .venv/bin/python benchmarks/bench_rig.py                 # all (~12 min, loaded 2 cores)
    .venv/bin/python benchmarks/bench_rig.py --quick         # a smoke run (~20 s)
    .venv/bin/python benchmarks/bench_rig.py --skip-timing --trials 40

All errors are in metres (each estimate's lengths divided by the true scale of the camera whose
units it is in) and degrees.
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
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import scipy

from acs_cli.core import se3
from acs_cli.core.relpose import estimate_relpose
from acs_cli.core.rig_solve import CameraTrack, RigEstimate, estimate_rig
from acs_cli.errors import DegenerateMotionError
from sample_data_gen.rig_sim import (
    SAMPLE_JOINTS,
    EdgeTruth,
    RigRecording,
    make_edges,
    rig_recording,
)

Joints = tuple[tuple[str, tuple[str, str], str], ...]

#: The issue's pose noise (per axis).
SIGMA_ROT_DEG = 0.3
SIGMA_TRANS = 0.01
#: The timing rigs: the first ``m - 1`` edges make a rig of ``m`` cameras (a tree mixing
#: ball, hinge and rigid joints: cam0-cam1-cam2-cam6-cam7 and cam0-cam3-cam4-cam5).
TREE_JOINTS: Joints = (
    ("j01", ("cam0", "cam1"), "ball"),
    ("h12", ("cam1", "cam2"), "hinge"),
    ("r03", ("cam0", "cam3"), "rigid"),
    ("j34", ("cam3", "cam4"), "ball"),
    ("h45", ("cam4", "cam5"), "hinge"),
    ("j26", ("cam2", "cam6"), "ball"),
    ("r67", ("cam6", "cam7"), "rigid"),
)
TIMING_UNKNOWN_SCALE = ("cam1",)
#: All-ball rigs for the comparison with the two-camera self-calibration, and their cameras
#: with unknown scale.
BALL_CHAIN: Joints = (
    ("j01", ("cam0", "cam1"), "ball"),
    ("j12", ("cam1", "cam2"), "ball"),
    ("j23", ("cam2", "cam3"), "ball"),
)
BALL_STAR: Joints = (
    ("j01", ("cam0", "cam1"), "ball"),
    ("j02", ("cam0", "cam2"), "ball"),
    ("j03", ("cam0", "cam3"), "ball"),
)
ACCURACY_RIGS: tuple[tuple[str, Joints, tuple[str, ...]], ...] = (
    ("ball chain cam0-cam1-cam2-cam3, cam2 of unknown scale", BALL_CHAIN, ("cam2",)),
    ("ball star around cam0, all of known scale", BALL_STAR, ()),
)
MIXED_UNKNOWN_SCALE = ("cam4",)

FULL_CAMERAS = (2, 3, 4, 6, 8)
FULL_FRAMES = (100, 500, 2000, 5000)
QUICK_CAMERAS = (2, 4)
QUICK_FRAMES = (100, 500)
_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def load() -> str:
    return "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg()) if hasattr(os, "getloadavg") else "?"


def machine_info() -> str:
    threads = {k: os.environ[k] for k in _THREAD_VARS if k in os.environ}
    return (
        f"{platform.platform()}, Python {platform.python_version()}, numpy {np.__version__}, "
        f"scipy {scipy.__version__}, {os.cpu_count()} CPUs, BLAS threads "
        + (", ".join(f"{k}={v}" for k, v in threads.items()) or "default")
    )


def tracks(rec: RigRecording) -> dict[str, CameraTrack]:
    n = rec.timestamps.size
    return {
        c: CameraTrack(T, np.ones(n, dtype=bool), rec.unknown_scale[c])
        for c, T in rec.T_wc_c.items()
    }


def rot_err_deg(R_true: np.ndarray, R_est: np.ndarray) -> float:
    return float(np.degrees(np.linalg.norm(se3.rotvec_from_matrix(R_true.T @ R_est))))


def rms(values: Sequence[float]) -> float:
    return float(np.sqrt(np.mean(np.square(values))))


def table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


# --------------------------------------------------------------------------- 1. timing


def timing_joints(m: int) -> Joints:
    if not 2 <= m <= len(TREE_JOINTS) + 1:
        raise ValueError(f"rigs of 2 to {len(TREE_JOINTS) + 1} cameras")
    return TREE_JOINTS[: m - 1]


def worst_joint_error(est: RigEstimate, rec: RigRecording) -> float:
    """Largest joint-position error (m) over every edge and side, a sanity check."""
    mu = rec.mu[rec.topology.reference]
    worst = 0.0
    for name, e in est.edges.items():
        t = rec.edges[name]
        for c, o in ((t.between[0], t.o_p), (t.between[1], t.o_q)):
            if c in e.position_in:
                worst = max(worst, float(np.linalg.norm(e.position_in[c] / mu - o)))
    return worst


def run_timing(
    cameras: Sequence[int], frames: Sequence[int], repeat: int, max_seconds: float, seed: int
) -> str:
    load_start = load()
    # warm-up: imports (scipy.stats is imported lazily by the outlier test) and first calls
    rec = rig_recording(np.random.default_rng(seed), 60, joints=timing_joints(2))
    estimate_rig(rec.topology, tracks(rec))
    times: dict[tuple[int, int], float | None] = {}
    runs: dict[tuple[int, int], int] = {}
    for m in cameras:
        too_long = False
        for n in frames:
            if too_long:
                times[m, n] = None
                continue
            rng = np.random.default_rng([seed, m, n])
            rec = rig_recording(
                rng,
                n,
                joints=timing_joints(m),
                unknown_scale=TIMING_UNKNOWN_SCALE,
                sigma_rot_deg=SIGMA_ROT_DEG,
                sigma_trans=SIGMA_TRANS,
            )
            tr = tracks(rec)
            best, done = float("inf"), 0
            while done < repeat:
                done += 1
                t0 = time.perf_counter()
                est = estimate_rig(rec.topology, tr)
                best = min(best, time.perf_counter() - t0)
                if best > max_seconds:
                    break  # one run is enough to know this cell is out of budget
            times[m, n], runs[m, n] = best, done
            err = worst_joint_error(est, rec)
            log(
                f"  {m} cameras x {n:>5} frames: {best:8.2f} s  ({est.iterations} evaluations, "
                f"worst joint error {100 * err:.2f} cm, load {load()})"
            )
            too_long = best > max_seconds
    head = ["cameras (joints)", *(f"{n} frames" for n in frames)]
    rows = []
    for m in cameras:
        kinds = [t for _, _, t in timing_joints(m)]
        what = ", ".join(f"{kinds.count(k)} {k}" for k in ("ball", "hinge", "rigid") if k in kinds)
        cells = [
            "—"
            if (t := times[m, n]) is None
            else f"{t:.2f}" + ("" if runs[m, n] == repeat else "¹")
            for n in frames
        ]
        rows.append([f"{m} ({what})", *cells])
    return "\n".join(
        [
            f"Seconds per `estimate_rig` call, best of {repeat}; pose noise {SIGMA_ROT_DEG} deg / "
            f"{SIGMA_TRANS} m; cam1 of unknown scale; seed {seed}. A cell over {max_seconds:g} s "
            "is one run (¹), and the row's larger frame counts are left out (—).",
            "",
            table(head, rows),
            "",
            f"Machine: {machine_info()}; load average (1, 5, 15 min) {load_start} at the start, "
            f"{load()} at the end.",
        ]
    )


# --------------------------------------------------------------------------- 2. accuracy


def chain_poses(rec: RigRecording, T_q_p: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``T_cam_ref`` of every camera from one ``T_q_p`` per edge (metres)."""
    out = {rec.topology.reference: np.eye(4)}
    for step in rec.topology.tree_order():
        T = T_q_p[step.joint.name]
        out[step.target] = (T if step.forward else se3.invert_transforms(T)) @ out[step.source]
    return out


def accuracy_trial(
    rec: RigRecording, errors: dict[tuple[str, str, str], list[float]], with_pairs: bool
) -> None:
    """Append one trial's errors to ``errors[(item, quantity, "pair" | "rig")]``."""
    ref = rec.topology.reference
    truth = rec.T_cam_ref(0)
    mu = rec.mu
    est = estimate_rig(rec.topology, tracks(rec))
    pair_T: dict[str, np.ndarray] = {}
    for j in rec.topology.joints:
        p, q = j.between
        t = rec.edges[j.name]
        T_true = truth[q] @ se3.invert_transforms(truth[p])
        T_rig = est.cameras[q].T_cam_ref @ se3.invert_transforms(est.cameras[p].T_cam_ref)
        # (T_q_p, metres per unit of its translation); joint positions in metres
        got = {"rig": (T_rig, 1.0 / mu[ref])}
        e = est.edges[j.name]
        pos = {}
        if j.type in ("ball", "hinge"):
            pos["rig"] = (e.position_in[p] / mu[ref], e.position_in[q] / mu[ref])
        if with_pairs:
            scale = rec.unknown_scale[p] or rec.unknown_scale[q]
            pe = estimate_relpose(rec.T_wc_c[p], rec.T_wc_c[q], None, unknown_scale=scale)
            # T_b_a's translation is in B's units, o_a in A's, o_b in B's
            got["pair"] = (pe.T_b_a, 1.0 / mu[q])
            pos["pair"] = (pe.position_in_a / mu[p], pe.position_in_b / mu[q])
            T_m = pe.T_b_a.copy()
            T_m[:3, 3] /= mu[q]
            pair_T[j.name] = T_m
        for who, (T, s) in got.items():
            errors.setdefault((j.name, "rot (deg)", who), []).append(
                rot_err_deg(T_true[:3, :3], T[:3, :3])
            )
            errors.setdefault((j.name, "trans (m)", who), []).append(
                float(np.linalg.norm(T[:3, 3] * s - T_true[:3, 3]))
            )
            if j.type in ("ball", "hinge"):
                o_p, o_q = pos[who]
                errors.setdefault((j.name, f"o in {p} (m)", who), []).append(
                    float(np.linalg.norm(o_p - t.o_p))
                )
                errors.setdefault((j.name, f"o in {q} (m)", who), []).append(
                    float(np.linalg.norm(o_q - t.o_q))
                )
        if j.type == "hinge" and t.axis_p is not None:
            u = e.axis_in[p]
            errors.setdefault((j.name, "axis (deg)", "rig"), []).append(
                float(np.degrees(np.arccos(min(1.0, abs(float(u @ t.axis_p))))))
            )
    chained = chain_poses(rec, pair_T) if with_pairs else {}
    for c in rec.topology.cameras:
        if c == ref:
            continue
        cands = {"rig": (est.cameras[c].T_cam_ref, 1.0 / mu[ref])}
        if with_pairs:
            cands["pair"] = (chained[c], 1.0)
        for who, (T, s) in cands.items():
            key = f"{c} T_cam_ref"
            errors.setdefault((key, "rot (deg)", who), []).append(
                rot_err_deg(truth[c][:3, :3], T[:3, :3])
            )
            errors.setdefault((key, "trans (m)", who), []).append(
                float(np.linalg.norm(T[:3, 3] * s - truth[c][:3, 3]))
            )
    if not with_pairs:
        for c, s in rec.scale().items():
            if est.cameras[c].scale_std is not None:
                errors.setdefault((f"{c} scale", "relative error", "rig"), []).append(
                    abs(est.cameras[c].scale / s - 1.0)
                )


def ratio_interval(pair: np.ndarray, rig: np.ndarray, rng: np.random.Generator) -> str:
    """90% paired-bootstrap interval of RMS(rig) / RMS(pair) over trials."""
    idx = rng.integers(0, pair.size, size=(2000, pair.size))
    r = np.sqrt(np.mean(rig[idx] ** 2, axis=1) / np.mean(pair[idx] ** 2, axis=1))
    lo, hi = np.quantile(r, [0.05, 0.95])
    return f"{lo:.2f}-{hi:.2f}"


def fmt(v: float, quantity: str) -> str:
    return f"{100 * v:.2f} cm" if "(m)" in quantity else f"{v:.3f}"


def run_accuracy(trials: int, frames: int, seed: int) -> str:
    out: list[str] = []
    boot = np.random.default_rng(12345)
    for title, joints, unknown in ACCURACY_RIGS:
        errors: dict[tuple[str, str, str], list[float]] = {}
        t0 = time.perf_counter()
        for trial in range(trials):
            rng = np.random.default_rng([seed, 9, trial, len(out)])
            rec = rig_recording(
                rng,
                frames,
                joints=joints,
                unknown_scale=unknown,
                sigma_rot_deg=SIGMA_ROT_DEG,
                sigma_trans=SIGMA_TRANS,
            )
            accuracy_trial(rec, errors, with_pairs=True)
        log(f"  {title}: {trials} trials in {time.perf_counter() - t0:.1f} s")
        rows = []
        for item, quantity, who in errors:
            if who != "pair":
                continue
            pair = np.asarray(errors[item, quantity, "pair"])
            rig = np.asarray(errors[item, quantity, "rig"])
            ratio = rms(rig) / rms(pair)
            rows.append(
                [
                    item,
                    quantity.replace(" (m)", ""),
                    fmt(rms(pair), quantity),
                    fmt(rms(rig), quantity),
                    f"{ratio:.2f}",
                    ratio_interval(pair, rig, boot),
                ]
            )
        head = ["edge / camera", "quantity", "RMS pair", "RMS rig", "rig / pair", "90% interval"]
        out += [f"**{title}** ({trials} trials, {frames} frames)", "", table(head, rows), ""]
    # the mixed rig: only the rig solve calibrates its hinge and rigid edges
    errors = {}
    t0 = time.perf_counter()
    for trial in range(trials):
        rng = np.random.default_rng([seed, 10, trial])
        rec = rig_recording(
            rng,
            frames,
            joints=SAMPLE_JOINTS,
            unknown_scale=MIXED_UNKNOWN_SCALE,
            sigma_rot_deg=SIGMA_ROT_DEG,
            sigma_trans=SIGMA_TRANS,
        )
        accuracy_trial(rec, errors, with_pairs=False)
    log(f"  mixed rig: {trials} trials in {time.perf_counter() - t0:.1f} s")
    kinds = {name: t for name, _, t in SAMPLE_JOINTS}
    rows = []
    for (item, quantity, _), v in errors.items():
        name = item.split()[0]
        label = f"{item} ({kinds[name]})" if name in kinds else item
        rows.append(
            [label, quantity.replace(" (m)", ""), fmt(rms(v), quantity), fmt(max(v), quantity)]
        )
    out += [
        "**mixed rig** `SAMPLE_JOINTS`: cam0 -rigid- cam1, cam0 -ball- cam2 -hinge- cam3 -rigid- "
        f"cam4, cam4 of unknown scale ({trials} trials, {frames} frames; rig solve only)",
        "",
        table(["edge / camera", "quantity", "RMS rig", "worst"], rows),
    ]
    return "\n".join(
        [
            f"Pose noise {SIGMA_ROT_DEG} deg / {SIGMA_TRANS} m, reference frame 0. Pair: "
            "`estimate_relpose(T_p, T_q, None, unknown_scale=...)` (self-calibrated) on the "
            "edge's two tracks alone; its `T_cam_ref` rows chain the pairs along the tree "
            "(translations brought to metres with the true scales). Rig: `estimate_rig` on all "
            "tracks. The interval is a 90% paired bootstrap over trials of the ratio.",
            "",
            *out,
        ]
    )


# --------------------------------------------------------------------------- 3. degeneracy

PLANAR: Joints = (("h01", ("cam0", "cam1"), "hinge"),)


def planar_truck(rng: np.random.Generator) -> RigRecording:
    """A truck (cam0) and its trailer (cam1) on flat ground (as in the unit tests)."""
    edges = make_edges(rng, PLANAR)
    z = np.array([0.0, 0.0, 1.0])
    o = edges["h01"].o_p - (edges["h01"].o_p @ z) * z
    R0 = se3.matrix_from_rotvec(np.array([0.0, 0.0, 0.4]))
    edges["h01"] = EdgeTruth("h01", ("cam0", "cam1"), "hinge", R0, o, edges["h01"].o_q, z)
    return rig_recording(
        rng,
        100,
        joints=PLANAR,
        edges=edges,
        planar=True,
        sigma_rot_deg=SIGMA_ROT_DEG,
        sigma_trans=SIGMA_TRANS,
    )


def run_degenerate(seed: int) -> str:
    rec = planar_truck(np.random.default_rng(seed))
    try:
        estimate_rig(rec.topology, tracks(rec))
    except DegenerateMotionError as exc:
        return "\n".join(
            [
                "A truck (cam0) and trailer (cam1) on flat ground, hinge `h01` about the "
                "vertical, 100 frames: `estimate_rig` raises `DegenerateMotionError`:",
                "",
                "> " + exc.message,
            ]
        )
    return "NOT RECOGNISED: the planar hinge solved without an error"


# --------------------------------------------------------------------------- main


def parse_ints(text: str) -> list[int]:
    return [int(s) for s in text.split(",") if s.strip()]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cameras", type=parse_ints, default=list(FULL_CAMERAS), help="e.g. 2,4,6")
    ap.add_argument("--frames", type=parse_ints, default=list(FULL_FRAMES), help="e.g. 100,2000")
    ap.add_argument("--repeat", type=int, default=3, help="runs per timing cell; best is kept")
    ap.add_argument(
        "--max-seconds",
        type=float,
        default=30.0,
        help="skip a row's larger frame counts once a cell takes longer than this",
    )
    ap.add_argument("--trials", type=int, default=40, help="seeded recordings for accuracy")
    ap.add_argument("--accuracy-frames", type=int, default=100)
    ap.add_argument(
        "--quick", action="store_true", help="2 and 4 cameras, 100 and 500 frames, 5 trials"
    )
    ap.add_argument("--skip-timing", action="store_true")
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, help="also write the Markdown report here")
    args = ap.parse_args(argv)
    cameras, frames, trials, repeat = args.cameras, args.frames, args.trials, args.repeat
    if args.quick:
        cameras, frames, trials, repeat = list(QUICK_CAMERAS), list(QUICK_FRAMES), 5, 1

    parts = [f"Date: {dt.datetime.now().astimezone().isoformat(timespec='seconds')}", ""]
    if not args.skip_timing:
        log("timing")
        parts += [
            "## Time against cameras x frames",
            "",
            run_timing(cameras, frames, repeat, args.max_seconds, args.seed),
            "",
        ]
    if not args.skip_accuracy:
        log("accuracy")
        load_start = load()
        acc = run_accuracy(trials, args.accuracy_frames, args.seed)
        parts += [
            "## Accuracy: rig solve against the two-camera commands",
            "",
            acc,
            "",
            f"Load average {load_start} at the start, {load()} at the end.",
            "",
        ]
    parts += ["## Degenerate motion, named edge by edge", "", run_degenerate(args.seed), ""]
    report = "\n".join(parts)
    print(report, flush=True)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(report + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
