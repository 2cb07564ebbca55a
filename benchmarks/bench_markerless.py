"""Markerless calibration (issue 10): rendered textured video -> SfM -> relative pose and
scale factor.

Per seed, :func:`sample_data_gen.textured.render_markerless` renders the two cameras of a
ball-jointed rig moving through a textured room (60 frames each at 30 Hz, 640x480). Each
camera's trajectory comes from ``acscal poses --sfm`` (``run_sfm_poses``, 2048 SIFT features,
sequential matching with loop closure), with the intrinsics given (the renderer's, as from a
board session) or self-calibrated by COLMAP (``--self-calibrated``); then ``acscal relpose
--self-calibrate --unknown-scale`` (``run_relpose``). Printed (Markdown): per seed, the
registered fraction, SfM's seconds per frame (wall clock, both cameras), the error of
``phi_ba`` and of the relative rotation and translation (metres, through the truth's units).

    .venv/bin/python benchmarks/bench_markerless.py --seeds 0 1         # ~4 min per seed here
    .venv/bin/python benchmarks/bench_markerless.py --seeds 0 --self-calibrated
"""

# ruff: noqa: E402  (BLAS threads must be set before numpy is imported)
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import dataclasses
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml

from acs_cli.core import se3
from acs_cli.io.artifacts import make_header
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.trajectory import read_trajectory
from acs_cli.stages.poses import SfmPosesConfig, run_sfm_poses
from acs_cli.stages.relpose import RelposeConfig, run_relpose
from sample_data_gen.textured import render_markerless


def _intrinsics(truth: dict, cam: str, path: Path) -> Path:
    t = truth[f"cam_{cam}"]
    art = IntrinsicsArtifact(
        model="pinhole",
        image_size=(int(t["image_size"][0]), int(t["image_size"][1])),
        camera_matrix=np.asarray(t["K"], dtype=float),
        distortion=np.asarray(t["dist"], dtype=float),
    )
    header = make_header("intrinsics", {}, "the renderer's camera", {}, {})
    dataclasses.replace(art, header=header).save(path)
    return path


def _unit(T: np.ndarray) -> float:
    """Mean distance between consecutive camera centres (the SfM unit, in the truth's)."""
    return float(np.mean(np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1)))


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--self-calibrated", action="store_true")
    ap.add_argument("--keep", type=Path, help="keep each seed's files under this folder")
    args = ap.parse_args(argv)
    rows = []
    for seed in args.seeds:
        with tempfile.TemporaryDirectory() as tmp:
            root = Path(tmp) if args.keep is None else args.keep / f"seed{seed}"
            data = render_markerless(root, seed=seed, frames=60)
            truth = yaml.safe_load((data / "truth.yaml").read_text())
            poses, registered, n_all, sec = {}, 0, 0, 0.0
            for cam in ("a", "b"):
                intr = None
                if not args.self_calibrated:
                    intr = _intrinsics(truth, cam, root / f"intr_{cam}.yaml")
                poses[cam] = root / f"poses_{cam}.npz"
                t0 = time.perf_counter()
                run = run_sfm_poses(
                    data / f"cam_{cam}", intr, poses[cam], SfmPosesConfig(max_features=2048)
                )
                sec += time.perf_counter() - t0
                registered += len(run.trajectory)
                n_all += 60
                print(
                    f"seed {seed} cam {cam}: {len(run.trajectory)}/60 registered", file=sys.stderr
                )
            rel = run_relpose(
                poses["a"], poses["b"], None, root / "relpose.yaml",
                RelposeConfig(unknown_scale=True, self_calibrate=True),
            ).estimate  # fmt: skip
            ta, tb = (
                read_trajectory(data / "truth_a.tum", "tum"),
                read_trajectory(data / "truth_b.tum", "tum"),
            )
            k = rel.reference
            T_b_a = se3.invert_transforms(tb.T_world_cam[k]) @ ta.T_world_cam[k]
            phi_true = _unit(ta.T_world_cam) / _unit(tb.T_world_cam)
            rot = float(se3.rotation_angle_deg(T_b_a[:3, :3].T @ rel.T_b_a[:3, :3]))
            t_err = float(np.linalg.norm(rel.T_b_a[:3, 3] * _unit(tb.T_world_cam) - T_b_a[:3, 3]))
            rows.append((seed, registered / n_all, sec / n_all,
                         100 * abs(rel.phi_ba / phi_true - 1), rot, t_err,
                         float(np.linalg.norm(T_b_a[:3, 3]))))  # fmt: skip
    mode = "self-calibrated by COLMAP" if args.self_calibrated else "given (the renderer's)"
    print(f"intrinsics {mode}; 2 cameras x 60 frames, 640x480\n")
    print("| seed | registered | SfM s/frame | phi_ba error | rotation error | translation error "
          "(of \\|t\\|) |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for seed, reg, spf, phi, rot, t_err, t_norm in rows:
        print(f"| {seed} | {100 * reg:.0f}% | {spf:.2f} | {phi:.2f}% | {rot:.2f} deg | "
              f"{1000 * t_err:.1f} mm ({1000 * t_norm:.0f} mm) |")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
