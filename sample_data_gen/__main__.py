"""``python -m sample_data_gen OUT_DIR``: write synthetic ACS recordings.

Without ``--scenario`` it writes the sample set (one rig: ``fixed_joint``, ``overlap``,
``general``, ``general_scaled``, ``fixed_joint_scaled``); with it, one scenario into
``OUT_DIR``. With ``--rig`` it writes the five-camera rig (``cam0.tum`` .. ``cam4.tum``,
``truth.yaml``, ``config.yaml``) into ``OUT_DIR``. With ``--markerless`` it renders the
markerless sample (:mod:`sample_data_gen.textured`: two cameras of a rig filming a textured
room, 640x480 at 30 fps, images and truth) into ``OUT_DIR/markerless``. With ``--aprilgrid``
or ``--charuco`` it renders one camera filming Kalibr's AprilGrid or a ChArUco board
(:mod:`sample_data_gen.target_render`: half the frames show 30-70 % of the target; images,
``target.yaml``, ``truth.yaml`` and the true corner projections) into ``OUT_DIR/aprilgrid``
or ``OUT_DIR/charuco``.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from sample_data_gen.target_render import default_target, render_target_sequence
from sample_data_gen.textured import render_markerless
from sample_data_gen.writer import (
    RIG_NOISE,
    SCENARIOS,
    write_rig_recording,
    write_sample_set,
    write_scenario,
)


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m sample_data_gen",
        description="Write synthetic articulated-camera recordings (TUM) and their truth.yaml.",
    )
    p.add_argument("out_dir", metavar="OUT_DIR", help="folder to write into (created)")
    p.add_argument(
        "--scenario",
        choices=SCENARIOS,
        help="write one scenario into OUT_DIR (default: the whole sample set in sub-folders)",
    )
    p.add_argument(
        "--rig",
        action="store_true",
        help="write the five-camera rig (cam0-cam4: rigid, ball, hinge, rigid joints; cam4 of "
        "unknown scale) with its truth.yaml and a run config config.yaml into OUT_DIR",
    )
    p.add_argument(
        "--markerless",
        action="store_true",
        help="render the markerless sample into OUT_DIR/markerless: images of the two cameras "
        "of a rig moving through a textured room (no board), for structure-from-motion, with "
        "truth.yaml and the true trajectories truth_a.tum, truth_b.tum",
    )
    for kind, what in (("aprilgrid", "Kalibr's 6x6 AprilGrid"), ("charuco", "an 11x8 ChArUco")):
        p.add_argument(
            f"--{kind}",
            action="store_true",
            help=f"render one camera filming {what} into OUT_DIR/{kind} (half the frames show "
            "30-70%% of it), with target.yaml, truth.yaml and truth_corners.npz",
        )
    p.add_argument(
        "--time-offset",
        type=float,
        default=None,
        metavar="SECONDS",
        help="with --markerless: camera B's image stamped t shows the rig at t + SECONDS "
        "(default 0)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--frames",
        type=int,
        default=None,
        help="poses per camera (default 30; 100 with --rig; 60 images with --markerless; 30 "
        "images with --aprilgrid, --charuco)",
    )
    p.add_argument(
        "--rot-noise",
        type=float,
        default=None,
        metavar="DEG",
        help="rotation noise per axis, degrees (default 0 for a scenario, 0.6 for the set, "
        f"{RIG_NOISE[0]} for the rig)",
    )
    p.add_argument(
        "--trans-noise",
        type=float,
        default=None,
        metavar="M",
        help="translation noise per axis, metres (default 0 for a scenario, 0.025 for the set, "
        f"{RIG_NOISE[1]} for the rig)",
    )
    p.add_argument("--mu-a", type=float, default=None, help="scale of A's translations")
    p.add_argument("--mu-b", type=float, default=None, help="scale of B's translations")
    p.add_argument("--hinge", action="store_true", help="a one-axis (hinge) joint")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.frames is not None and args.frames < 1:
        parser.error("--frames must be at least 1")
    for name in ("rot_noise", "trans_noise"):
        value = getattr(args, name)
        if value is not None and value < 0:
            parser.error(f"--{name.replace('_', '-')} must not be negative")
    for name in ("mu_a", "mu_b"):
        value = getattr(args, name)
        if value is not None and not value > 0:
            parser.error(f"--{name.replace('_', '-')} must be positive")
    if args.time_offset is not None and not args.markerless:
        parser.error("--time-offset needs --markerless")
    if args.time_offset is not None and not math.isfinite(args.time_offset):
        parser.error("--time-offset must be a finite number of seconds")
    targets = [k for k in ("aprilgrid", "charuco") if getattr(args, k)]
    if targets:
        others = ("scenario", "rot_noise", "trans_noise", "mu_a", "mu_b", "time_offset")
        given = [name for name in others if getattr(args, name) is not None]
        if args.rig or args.hinge or args.markerless or given:
            parser.error("--aprilgrid and --charuco take only --seed and --frames")
        for kind in targets:
            path = render_target_sequence(
                Path(args.out_dir) / kind,
                default_target(kind),
                seed=args.seed,
                frames=30 if args.frames is None else args.frames,
            )
            print(f"{kind}: {path}")
        return 0
    if args.markerless:
        others = ("scenario", "rot_noise", "trans_noise", "mu_a", "mu_b")
        if args.rig or args.hinge or any(getattr(args, name) is not None for name in others):
            parser.error(
                "--markerless takes only --seed, --frames and --time-offset "
                "(not --rig, --scenario, noise, scales or --hinge)"
            )
        path = render_markerless(
            args.out_dir,
            seed=args.seed,
            frames=60 if args.frames is None else args.frames,
            time_offset_s=0.0 if args.time_offset is None else args.time_offset,
        )
        print(f"markerless: {path}")
        return 0
    if args.rig:
        if args.scenario is not None:
            parser.error("--rig and --scenario exclude each other")
        if args.mu_a is not None or args.mu_b is not None or args.hinge:
            parser.error("--mu-a, --mu-b and --hinge need --scenario (not --rig)")
        write_rig_recording(
            args.out_dir,
            seed=args.seed,
            frames=100 if args.frames is None else args.frames,
            rot_noise_deg=RIG_NOISE[0] if args.rot_noise is None else args.rot_noise,
            trans_noise=RIG_NOISE[1] if args.trans_noise is None else args.trans_noise,
        )
        print(f"rig: {args.out_dir}")
        return 0
    frames = 30 if args.frames is None else args.frames
    if args.scenario is None:
        if args.mu_a is not None or args.mu_b is not None or args.hinge:
            parser.error("--mu-a, --mu-b and --hinge need --scenario")
        kwargs = {}
        if args.rot_noise is not None:
            kwargs["rot_noise_deg"] = args.rot_noise
        if args.trans_noise is not None:
            kwargs["trans_noise"] = args.trans_noise
        written = write_sample_set(args.out_dir, seed=args.seed, frames=frames, **kwargs)
        for name, path in written.items():
            print(f"{name}: {path}")
        return 0
    path = write_scenario(
        args.out_dir,
        args.scenario,
        seed=args.seed,
        frames=frames,
        rot_noise_deg=0.0 if args.rot_noise is None else args.rot_noise,
        trans_noise=0.0 if args.trans_noise is None else args.trans_noise,
        mu_a=1.0 if args.mu_a is None else args.mu_a,
        mu_b=1.0 if args.mu_b is None else args.mu_b,
        hinge=args.hinge,
    )
    print(f"{args.scenario}: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
