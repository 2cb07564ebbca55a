"""A rigid stereo pair as a rig against ``cv2.stereoCalibrate`` (issue 19).

OpenCV's 13 real stereo pairs (``../shared/data/opencv_chessboard``, relative to the
repository; ``--data`` to point elsewhere): 640x480, a 9x6 board, squares taken as 0.025 m.

Protocol:

1. Detections, once: ``acscal run`` on all 13 pairs (config ``world: shared``, cameras
   ``left``/``right`` with ``images``, a ``rigid`` joint, as
   ``tests/e2e/test_cli_stereo_rig.py``). Its ``cam_*/poses.npz`` corners are every method's
   corners (OpenCV's training corners and every evaluation's), and its detection caches are
   copied into every later run, so acscal's own runs read the same detections (checked:
   each run's NPZ corners equal these).
2. A training set (leave one pair out: the 12 others; or a random subset of 3, 5 or 8 pairs)
   is a folder of symlinks per camera and ``acscal run config.yaml`` on it, as a user runs it
   (``max_dt: 0.5``: the times are the frame numbers in the names, and the default, half the
   median interval, merges frames 7 and 8 of a subset 7, 8, 11 into one instant)
   (a subprocess; retried with ``--accept-weak`` if it exits 3, and counted). It gives the
   per-camera intrinsics (``cam_*/intrinsics.yaml``, each camera calibrated on its training
   images alone), ``T_right_left`` (``rig.yaml``: the pose-based solve, then the rig's bundle
   adjustment, intrinsics refined from 3 pairs on) and the bundle's intrinsics.
3. ``cv2.stereoCalibrate`` on the same training corners (default termination criteria):
   ``FIX_INTRINSIC`` with acscal's per-camera intrinsics of that training set (the issue's
   "same intrinsics"); flags ``0`` (OpenCV calibrates each camera itself, k3 free, then
   refines everything); ``USE_INTRINSIC_GUESS | FIX_K3`` from acscal's per-camera
   intrinsics (the model acscal's bundle adjustment refines: pinhole, k3 held at 0).
4. Prediction, for each pair not trained on: the left camera's board pose by PnP from its
   own corners (IPPE, then Levenberg-Marquardt) with the method's left intrinsics, chained
   through the method's ``T_right_left`` and projected with its right intrinsics; the error
   against the right camera's detected corners (px).

Methods: ``acscal run (rig.yaml T, bundle K)`` (what ``acscal run`` gives: rig.yaml's
``T_right_left`` and its ``bundle_adjustment`` intrinsics, refined, or the per-camera ones
where it held them); ``acscal rig.yaml T, per-camera K`` (the same ``T`` with
intrinsics.yaml's K, a diagnostic: that ``T`` was fitted with the bundle's intrinsics);
``acscal bundle: false, per-camera K`` (the rig stage alone again on the same poses NPZs
with ``bundle: false``: the pose-based solve, predicted with the per-camera intrinsics it was
solved from: acscal's side of "the same intrinsics"); and the three OpenCV rows.

Measures over the evaluated pairs: ``RMS all`` (point distance over every corner of every
evaluated pair), ``mean fold`` (mean of each pair's RMS), ``max fold``, ``RMS/coord`` (the
per-coordinate RMS, ``RMS all / sqrt(2)``) and ``wins`` (pairs where the method beats
``stereoCalibrate FIX_INTRINSIC``).

Run (about 4 minutes on 2 shared cores, most of it the ``acscal run`` subprocesses)::

    PYTHONPATH=. .venv/bin/python benchmarks/bench_stereo.py [--data DIR] [--subsets 5]
        [--sizes 3,5,8] [--seed 0] [--workdir DIR] [--save F.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from acs_cli.core import se3
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.rig import RigArtifact

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "opencv_chessboard"
SIZE = (640, 480)
SIDES = ("left", "right")
CONFIG = """\
schema_version: 2
output: out/
board: {cols: 9, rows: 6, square: 0.025}
world: shared
max_dt: 0.5
workers: 1
cameras:
  left: {images: left}
  right: {images: right}
joints:
  stereo: {between: [left, right], type: rigid}
"""
POSE_CONFIG = """\
schema_version: 2
output: out_pose/
world: shared
max_dt: 0.5
bundle: false
cameras:
  left: {poses: out/cam_left/poses.npz}
  right: {poses: out/cam_right/poses.npz}
joints:
  stereo: {between: [left, right], type: rigid}
"""
ACSCAL_BA = "acscal run (rig.yaml T, bundle K)"
ACSCAL_K = "acscal rig.yaml T, per-camera K"
ACSCAL_POSE = "acscal bundle: false, per-camera K"
CV_FIX = "stereoCalibrate FIX_INTRINSIC"
CV_FREE = "stereoCalibrate flags 0"
CV_GUESS = "stereoCalibrate GUESS|FIX_K3"
METHODS = (ACSCAL_BA, ACSCAL_K, ACSCAL_POSE, CV_FIX, CV_FREE, CV_GUESS)


@dataclass
class Camera:
    K: np.ndarray
    d: np.ndarray


@dataclass
class Fit:
    """One method's stereo calibration: ``T_right_left`` and the intrinsics it predicts with."""

    T: np.ndarray
    left: Camera
    right: Camera


@dataclass
class Detections:
    """The 13 pairs' corners, ``(n, m, 2)`` per camera, in one labelling of the board."""

    pairs: list[str]  # "01", "02", ...
    corners: dict[str, np.ndarray]
    X: np.ndarray  # (m, 3) board points, metres


def acscal_bin() -> str:
    exe = Path(sys.executable).with_name("acscal")
    return str(exe) if exe.exists() else "acscal"


def acscal_run(root: Path, pairs: list[str], data: Path, cache: Path | None) -> dict:
    """``acscal run`` on the given pairs in a fresh folder ``root``: its exit, seconds and
    whether ``--accept-weak`` was needed."""
    if root.exists():
        shutil.rmtree(root)
    for s in SIDES:
        (root / s).mkdir(parents=True)
        for p in pairs:
            (root / s / f"{s}{p}.jpg").symlink_to(data / f"{s}{p}.jpg")
        if cache is not None:
            (root / "out" / f"cam_{s}").mkdir(parents=True)
            shutil.copy(cache / f"cam_{s}" / "intrinsics.detections.npz", root / "out" / f"cam_{s}")
    (root / "config.yaml").write_text(CONFIG)
    t0 = time.perf_counter()
    cmd = [acscal_bin(), "run", "config.yaml"]
    res = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    weak = False
    if res.returncode == 3:
        weak = True
        refusal = [ln for ln in res.stderr.splitlines() if "error" in ln.lower()][:1]
        res = subprocess.run([*cmd, "--accept-weak"], cwd=root, capture_output=True, text=True)
    else:
        refusal = []
    if res.returncode != 0:
        raise RuntimeError(f"acscal run in {root} exited {res.returncode}:\n{res.stderr}")
    # the rig stage alone again on the same poses, without the bundle adjustment
    (root / "config_pose.yaml").write_text(POSE_CONFIG)
    cmd = [acscal_bin(), "run", "config_pose.yaml", *(["--accept-weak"] if weak else [])]
    pose = subprocess.run(cmd, cwd=root, capture_output=True, text=True)
    if pose.returncode != 0:
        raise RuntimeError(f"acscal run config_pose.yaml in {root}:\n{pose.stderr}")
    return {
        "seconds": time.perf_counter() - t0,
        "weak": weak,
        "refusal": refusal,
        "stderr": res.stderr,
    }


def load_detections(out: Path) -> Detections:
    npz = {s: np.load(out / f"cam_{s}" / "poses.npz") for s in SIDES}
    names = {s: [str(n) for n in npz[s]["image_names"]] for s in SIDES}
    pairs = [n[len("left") : -len(".jpg")] for n in names["left"]]
    assert [n[len("right") : -len(".jpg")] for n in names["right"]] == pairs, names
    X = np.asarray(npz["left"]["board_points"], float)
    assert np.array_equal(X, npz["right"]["board_points"])
    corners = {s: np.asarray(npz[s]["corners"], float) for s in SIDES}
    assert all(np.isfinite(c).all() for c in corners.values())
    return Detections(pairs, corners, X)


def same_labelling(det: Detections) -> None:
    """Left and right label every pair's board alike (both NPZs from one run whose rig turned
    neither): stereoCalibrate on all pairs fits to a fraction of a pixel."""
    n = len(det.pairs)
    rms, *_ = cv2.stereoCalibrate(
        [det.X.astype(np.float32)] * n,
        [c.astype(np.float32) for c in det.corners["left"]],
        [c.astype(np.float32) for c in det.corners["right"]],
        None, None, None, None, SIZE, flags=0,
    )  # fmt: skip
    assert rms < 1.0, f"left and right label the board differently? stereo RMS {rms:.2f} px"


def check_same_detections(out: Path, det: Detections) -> float:
    """The largest difference (px) between a run's NPZ corners and the reference detections,
    either labelling of the board."""
    worst = 0.0
    for s in SIDES:
        d = np.load(out / f"cam_{s}" / "poses.npz")
        for name, c in zip(d["image_names"], d["corners"], strict=True):
            ref = det.corners[s][det.pairs.index(str(name)[len(s) : -len(".jpg")])]
            worst = max(worst, min(np.abs(c - ref).max(), np.abs(c[::-1] - ref).max()))
    return float(worst)


def acscal_fits(out: Path, frames: int) -> tuple[Fit, Fit, bool]:
    """acscal's ``T_right_left`` with its per-camera intrinsics, and with the bundle's (and
    whether there was a bundle adjustment)."""
    rig = RigArtifact.load(out / "rig.yaml")
    T = rig.T_a_b("right", "left")
    j = rig.joints["stereo"]
    assert j.frames_used + j.frames_rejected == frames, (out, j.frames_used, frames)
    own = {}
    for s in SIDES:
        a = IntrinsicsArtifact.load(out / f"cam_{s}" / "intrinsics.yaml")
        assert a.model == "pinhole"
        own[s] = Camera(a.camera_matrix, a.distortion)
    ba = rig.bundle_adjustment
    if ba:
        refined = {s: Camera(ba[s].camera_matrix, ba[s].distortion) for s in SIDES}
    else:
        refined = own
    return Fit(T, own["left"], own["right"]), Fit(T, refined["left"], refined["right"]), bool(ba)


def opencv_fits(det: Detections, train: list[int], own: Fit) -> dict[str, Fit]:
    X = [det.X.astype(np.float32)] * len(train)
    cl = [det.corners["left"][i].astype(np.float32) for i in train]
    cr = [det.corners["right"][i].astype(np.float32) for i in train]
    out = {}
    for name, flags, start in (
        (CV_FIX, cv2.CALIB_FIX_INTRINSIC, own),
        (CV_FREE, 0, None),
        (CV_GUESS, cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3, own),
    ):
        if start is None:
            K1 = d1 = K2 = d2 = None
        else:
            K1, d1 = start.left.K.copy(), start.left.d.copy()
            K2, d2 = start.right.K.copy(), start.right.d.copy()
        _, K1, d1, K2, d2, R, t, _, _ = cv2.stereoCalibrate(
            X, cl, cr, K1, d1, K2, d2, SIZE, flags=flags
        )
        out[name] = Fit(
            se3.transforms_from_rt(R, t.ravel()), Camera(K1, d1.ravel()), Camera(K2, d2.ravel())
        )
    return out


def predict_errors(fit: Fit, det: Detections, i: int) -> np.ndarray:
    """``(m, 2)`` predicted minus detected corners of the right camera in pair ``i``."""
    X = det.X
    cl = det.corners["left"][i]
    ok, rvec, tvec = cv2.solvePnP(X, cl, fit.left.K, fit.left.d, flags=cv2.SOLVEPNP_IPPE)
    assert ok
    rvec, tvec = cv2.solvePnPRefineLM(X, cl, fit.left.K, fit.left.d, rvec, tvec)
    T_left_board = se3.transforms_from_rt(cv2.Rodrigues(rvec)[0], tvec.ravel())
    T_right_board = fit.T @ T_left_board
    rv, _ = cv2.Rodrigues(T_right_board[:3, :3])
    proj, _ = cv2.projectPoints(X, rv, T_right_board[:3, 3], fit.right.K, fit.right.d)
    return proj.reshape(-1, 2) - det.corners["right"][i]


def experiment(det: Detections, train: list[int], work: Path, data: Path, cache: Path) -> dict:
    """Train every method on ``train`` and predict every other pair."""
    run = acscal_run(work, [det.pairs[i] for i in train], data, cache)
    diff = check_same_detections(work / "out", det)
    fit_k, fit_ba, bundled = acscal_fits(work / "out", len(train))
    pose = RigArtifact.load(work / "out_pose" / "rig.yaml")
    assert not pose.bundle_adjustment
    fit_pose = Fit(pose.T_a_b("right", "left"), fit_k.left, fit_k.right)
    fits = {ACSCAL_BA: fit_ba, ACSCAL_K: fit_k, ACSCAL_POSE: fit_pose}
    fits |= opencv_fits(det, train, fit_k)
    test = [i for i in range(len(det.pairs)) if i not in train]
    errors = {m: {det.pairs[i]: predict_errors(f, det, i) for i in test} for m, f in fits.items()}
    return {
        "train": [det.pairs[i] for i in train],
        "errors": errors,
        "bundled": bundled,
        "weak": run["weak"],
        "refusal": run["refusal"],
        "seconds": run["seconds"],
        "detections_max_diff_px": diff,
        "rejected": RigArtifact.load(work / "out" / "rig.yaml").joints["stereo"].frames_rejected,
        "baseline_m": {m: float(np.linalg.norm(f.T[:3, 3])) for m, f in fits.items()},
    }


def summary(exps: list[dict]) -> dict[str, dict[str, float]]:
    """Per method: the measures over every evaluated pair of every experiment."""
    out = {}
    for m in METHODS:
        per = [e for x in exps for e in x["errors"][m].values()]
        ref = [e for x in exps for e in x["errors"][CV_FIX].values()]
        rms = np.array([np.sqrt(np.mean(np.sum(e**2, axis=1))) for e in per])
        rms_ref = np.array([np.sqrt(np.mean(np.sum(e**2, axis=1))) for e in ref])
        allc = np.concatenate(per)
        out[m] = {
            "rms_all": float(np.sqrt(np.mean(np.sum(allc**2, axis=1)))),
            "mean_fold": float(rms.mean()),
            "median_fold": float(np.median(rms)),
            "max_fold": float(rms.max()),
            "rms_coord": float(np.sqrt(np.mean(allc**2))),
            "wins": int(np.sum(rms < rms_ref)),
            "n": int(rms.size),
        }
    return out


def table(s: dict[str, dict[str, float]]) -> str:
    rows = [
        "| method | RMS all (px) | mean fold | median fold | max fold | RMS/coord | beats FIX |",
        "|---|---|---|---|---|---|---|",
    ]
    for m, v in s.items():
        wins = "-" if m == CV_FIX else f"{v['wins']}/{v['n']}"
        rows.append(
            f"| {m} | {v['rms_all']:.4f} | {v['mean_fold']:.4f} | {v['median_fold']:.3f} | "
            f"{v['max_fold']:.3f} | {v['rms_coord']:.3f} | {wins} |"
        )
    return "\n".join(rows)


def fold_table(exps: list[dict]) -> str:
    head = "| left out | " + " | ".join(METHODS) + " |"
    rows = [head, "|---" * (len(METHODS) + 1) + "|"]
    for x in exps:
        (p,) = x["errors"][ACSCAL_K]
        cells = [np.sqrt(np.mean(np.sum(x["errors"][m][p] ** 2, axis=1))) for m in METHODS]
        rows.append(f"| {p} | " + " | ".join(f"{c:.3f}" for c in cells) + " |")
    return "\n".join(rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--sizes", default="3,5,8", help="training-set sizes of the subset study")
    ap.add_argument("--subsets", type=int, default=5, help="random subsets per size")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workdir", type=Path, help="keep the runs here (default: temporary)")
    ap.add_argument("--save", type=Path, help="write every pair's errors as JSON")
    args = ap.parse_args()
    if not args.data.is_dir():
        print(f"no data at {args.data}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    tmp = None
    if args.workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="bench_stereo_")
        work = Path(tmp.name)
    else:
        work = args.workdir
        work.mkdir(parents=True, exist_ok=True)
    try:
        # 1. detect once
        pairs_all = sorted(p.name[len("left") : -len(".jpg")] for p in args.data.glob("left*.jpg"))
        full = work / "all"
        run = acscal_run(full, pairs_all, args.data, None)
        det = load_detections(full / "out")
        assert det.pairs == pairs_all, (det.pairs, pairs_all)
        same_labelling(det)
        cache = full / "out"
        fit_k, _, _ = acscal_fits(full / "out", len(det.pairs))
        print(
            f"all {len(det.pairs)} pairs: acscal run {run['seconds']:.1f} s, baseline "
            f"{1000 * np.linalg.norm(fit_k.T[:3, 3]):.2f} mm",
            file=sys.stderr,
        )
        n = len(det.pairs)
        # 2. leave one pair out
        loo = []
        for k in range(n):
            train = [i for i in range(n) if i != k]
            x = experiment(det, train, work / f"loo_{det.pairs[k]}", args.data, cache)
            loo.append(x)
            print(
                f"leave out {det.pairs[k]}: "
                + ", ".join(
                    f"{m} {np.sqrt(np.mean(np.sum(e[det.pairs[k]] ** 2, axis=1))):.3f}"
                    for m, e in x["errors"].items()
                )
                + f" ({x['seconds']:.1f} s)",
                file=sys.stderr,
            )
        # 3. fewer pairs
        rng = np.random.default_rng(args.seed)
        sizes = [int(s) for s in args.sizes.split(",") if s]
        few: dict[int, list[dict]] = {}
        for size in sizes:
            few[size] = []
            for j in range(args.subsets):
                train = sorted(int(i) for i in rng.choice(n, size=size, replace=False))
                x = experiment(det, train, work / f"n{size}_{j}", args.data, cache)
                few[size].append(x)
                s = summary([x])
                print(
                    f"{size} pairs {x['train']}: "
                    + ", ".join(f"{m} {v['rms_all']:.3f}" for m, v in s.items())
                    + (" (acscal needed --accept-weak)" if x["weak"] else "")
                    + ("" if x["bundled"] else " (no rig bundle adjustment)")
                    + f" ({x['seconds']:.1f} s)",
                    file=sys.stderr,
                )
        worst = max(
            x["detections_max_diff_px"] for x in [*loo, *(y for v in few.values() for y in v)]
        )
        # report
        rej = sum(x["rejected"] for x in loo)
        print(f"## Leave one pair out ({n} folds, {n - 1} training pairs each; pairs rejected "
              f"by the rig {rej})\n")  # fmt: skip
        print(table(summary(loo)))
        print("\nRMS (px) of the left-out pair's right-camera corners, fold by fold:\n")
        print(fold_table(loo))
        for size, exps in few.items():
            weak = sum(x["weak"] for x in exps)
            rej = sum(x["rejected"] for x in exps)
            bundled = sum(x["bundled"] for x in exps)
            print(
                f"\n## {size} training pairs ({len(exps)} random subsets, seed {args.seed}; "
                f"every other pair predicted; acscal bundle-adjusted {bundled}/{len(exps)}, "
                f"--accept-weak needed {weak}/{len(exps)}, pairs rejected by the rig {rej})\n"
            )
            print(table(summary(exps)))
            print("\nsubsets: " + "; ".join(",".join(x["train"]) for x in exps))
        base = {m: [x["baseline_m"][m] * 1000 for x in loo] for m in METHODS}
        print("\nbaseline |t_right_left| over the leave-one-out folds (mm): " + "; ".join(
            f"{m} {np.mean(v):.2f} +- {np.std(v):.2f}" for m, v in base.items()
        ))  # fmt: skip
        print(
            f"\nlargest difference between a run's corners and the reference detections: "
            f"{worst:.2g} px; {time.perf_counter() - t0:.0f} s in all"
        )
        if args.save:
            doc = {
                "loo": [_jsonable(x) for x in loo],
                "few": {str(k): [_jsonable(x) for x in v] for k, v in few.items()},
            }
            args.save.write_text(json.dumps(doc))
    finally:
        if tmp is not None:
            tmp.cleanup()
    return 0


def _jsonable(x: dict) -> dict:
    out = {k: v for k, v in x.items() if k != "errors"}
    out["errors_px"] = {
        m: {p: e.tolist() for p, e in per.items()} for m, per in x["errors"].items()
    }
    return out


if __name__ == "__main__":
    sys.exit(main())
