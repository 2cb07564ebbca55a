"""Stds under errors correlated over time (issue 20, item 1): the model's covariance against
the block sandwich of :mod:`acs_cli.core.correlated`, on simulated motion capture.

Hip (ball) and knee (hinge) trials of :mod:`sample_data_gen.mocap_sim` (60 Hz, independent
pose noise 0.5 deg / 1 mm on both segments), solved by the rig engine with one shared world,
with three kinds of error on the moving segment:

- ``independent``: none beyond the independent noise (the stds must not change);
- ``drift``: a smooth random error in time (``--drift-mm``, and a fifth of it in degrees: a
  few sines of 0.15-0.8 Hz), as a tracker drifts or skin slides with muscle activity;
- ``slide``: a marker slide that is a fixed function of the flexion (``--slide-mm``), the
  simulator's skin-marker model;
- ``wobble`` (knee only): a hinge that is not quite one: the tibia turns off the axis by
  ``--wobble-deg`` RMS and its centre rolls by ``--roll-mm`` RMS along the femur, both smooth
  functions of the flexion (a real knee's ab/adduction and rolling);
- ``kinematics`` (hand-eye): a camera on a robot's flange, the robot sweeping smoothly through
  300 poses; the flange poses carry a kinematic error that depends on the configuration
  (``--kinematic-deg`` and ``--kinematic-mm`` RMS, smooth in the flange's orientation and
  position), as a robot's uncalibrated link lengths and offsets make; the quantity is the
  hand-eye transform (6 dof).

Per kind and quantity: error/std RMS (``sqrt(mean(d' C^-1 d / k))``, k = 3 for a point, 2
for a hinge point or axis) with the model's covariance and with the block sandwich, and the
share of trials whose covariance grew. Real data: ``bench_mocap.py --skip-sim`` (halves,
blocks, left against right).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_correlated.py            # ~5 min here
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
from acs_cli.core.relpose import estimate_relpose
from acs_cli.core.rig_solve import Recordings, estimate_rig
from sample_data_gen import mocap_sim as M
from sample_data_gen.acs_sim import add_pose_noise

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_mocap as BM

KINDS = ("independent", "drift", "slide", "wobble", "kinematics")
#: the quantities each kind is measured on
QUANTITIES = {
    "independent": ("hip centre", "knee axis", "knee point", "hand-eye"),
    "drift": ("hip centre", "knee axis", "knee point"),
    "slide": ("hip centre", "knee axis", "knee point"),
    "wobble": ("knee axis", "knee point"),
    "kinematics": ("hand-eye",),
}


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


def _wobble(
    rng: np.random.Generator, knee: M.MocapTrial, wobble_deg: float, roll_mm: float
) -> None:
    """Make the measured tibia of ``knee`` turn off the hinge and roll (module doc), in
    place: a rotation about an axis across the knee axis, through the knee centre, and a
    translation along the femur's x, each a smooth function of the flexion."""
    T_ft = np.linalg.solve(knee.truth["femur"], knee.truth["tibia"])
    theta = np.linalg.norm(se3.rotvec_from_matrix(T_ft[:, :3, :3] @ T_ft[0, :3, :3].T), axis=1)
    a = (theta - theta.mean()) / max(float(np.std(theta)), 1e-9)
    f = a + 0.4 * (a**2 - 1.0)  # smooth in the flexion, not linear
    f /= np.sqrt(np.mean(f**2))
    across = np.cross(M.KNEE_AXIS_IN_FEMUR, rng.standard_normal(3))
    across /= np.linalg.norm(across)
    R_w = se3.matrix_from_rotvec(np.radians(wobble_deg) * f[:, None] * across)
    # about the knee centre (in the femur), then rolled across the axis, along the femur's y
    roll = np.array([0.0, 1.0, 0.0]) - M.KNEE_AXIS_IN_FEMUR[1] * M.KNEE_AXIS_IN_FEMUR
    roll /= np.linalg.norm(roll)
    t_w = M.KNEE_IN_FEMUR - np.einsum("nij,j->ni", R_w, M.KNEE_IN_FEMUR)
    t_w += (roll_mm / 1000.0) * f[:, None] * roll
    E = se3.transforms_from_rt(R_w, t_w)  # in the femur's frame
    noise = np.linalg.solve(knee.truth["tibia"], knee.measured["tibia"])
    knee.measured["tibia"] = knee.truth["femur"] @ E @ T_ft @ noise


def hand_eye_trial(
    seed: int, frames: int, kin_deg: float, kin_mm: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A camera on a robot's flange (module doc): noisy ``T_world_cam``, the flange's
    ``T_base_flange`` with its kinematic error, and the true ``T_flange_cam``."""
    rng = np.random.default_rng([21, seed])
    t = np.arange(frames) / 10.0  # a robot sweeping: smooth, 10 poses a second
    rv = np.stack([M._smooth(rng, t, np.radians(35.0)) for _ in range(3)], axis=1)
    pos = np.stack([M._smooth(rng, t, 0.25) for _ in range(3)], axis=1) + np.array([0.6, 0.0, 0.5])
    T_base_flange = se3.transforms_from_rt(se3.matrix_from_rotvec(rv), pos)
    T_flange_cam = se3.transforms_from_rt(
        se3.matrix_from_rotvec(np.array([0.3, -0.5, 0.2])), np.array([0.05, 0.1, 0.12])
    )
    T_world_base = se3.transforms_from_rt(se3.matrix_from_rotvec(np.array([0.1, 2.0, -0.3])),
                                          np.array([0.3, -0.2, 1.5]))  # fmt: skip
    T_world_cam = T_world_base @ T_base_flange @ T_flange_cam
    # the kinematic error: a fixed smooth function of the configuration (the flange pose)
    x = np.concatenate([rv / np.radians(35.0), (pos - pos.mean(0)) / 0.25], axis=1)
    G = rng.standard_normal((6, 12)) / np.sqrt(12.0)
    feats = np.concatenate([x, np.sin(x)], axis=1)
    err = feats @ G.T
    err /= np.sqrt(np.mean(err**2, axis=0))
    err[:, :3] *= np.radians(kin_deg) / np.sqrt(3.0)
    err[:, 3:] *= kin_mm / 1000.0 / np.sqrt(3.0)
    E = se3.transforms_from_rt(se3.matrix_from_rotvec(err[:, :3]), err[:, 3:])
    flange = add_pose_noise(rng, T_base_flange @ E, 0.01, 0.0001)  # the controller's rounding
    cam = add_pose_noise(rng, T_world_cam, 0.05, 0.0005)  # the board's poses
    return cam, flange, T_flange_cam


def z2_hand_eye(est: object, T_flange_cam: np.ndarray) -> tuple[float, bool]:
    """The hand-eye transform's squared normalised error per dof (6)."""
    grew = bool(est.rig.correlated.detected)  # type: ignore[attr-defined]
    T = est.T_b_a  # type: ignore[attr-defined]
    C = est.covariance  # type: ignore[attr-defined]
    d = np.concatenate(
        [se3.rotvec_from_matrix(T_flange_cam[:3, :3].T @ T[:3, :3]), T[:3, 3] - T_flange_cam[:3, 3]]
    )
    return float(d @ np.linalg.solve(C, d)) / 6, grew


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
                n = args.frames
                quantities = QUANTITIES[kind]
                if "hand-eye" in quantities:
                    on = kind == "kinematics"
                    cam, flange, X = hand_eye_trial(
                        s, n, args.kinematic_deg * on, args.kinematic_mm * on
                    )
                    est = estimate_relpose(cam, flange, None, joint_type="rigid")
                    out.setdefault((kind, "hand-eye"), []).append(z2_hand_eye(est, X))
                if kind == "kinematics":
                    continue
                hip, knee = trial(kind, s, n, args.drift_mm, args.slide_mm)
                if kind == "wobble":
                    _wobble(np.random.default_rng([22, s]), knee, args.wobble_deg, args.roll_mm)
                one = Recordings.single(n, True)
                if "hip centre" in quantities:
                    h = estimate_rig(BM.HIP, BM.tracks_of(hip.measured), recordings=one)
                    out.setdefault((kind, "hip centre"), []).append(z2(h, "hip centre"))
                k = estimate_rig(BM.KNEE, BM.tracks_of(knee.measured), recordings=one)
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
    ap.add_argument("--wobble-deg", type=float, default=2.0)
    ap.add_argument("--roll-mm", type=float, default=5.0)
    ap.add_argument("--kinematic-deg", type=float, default=0.2)
    ap.add_argument("--kinematic-mm", type=float, default=1.0)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    before = run(args, model_only=True)
    after = run(args, model_only=False)
    print(
        f"## Stds under correlated errors ({args.seeds} seeds, {args.frames} frames at 60 Hz, "
        f"drift {args.drift_mm} mm, slide {args.slide_mm} mm, wobble {args.wobble_deg} deg "
        f"and roll {args.roll_mm} mm, kinematics {args.kinematic_deg} deg and "
        f"{args.kinematic_mm} mm)\n"
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
