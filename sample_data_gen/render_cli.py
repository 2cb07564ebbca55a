"""``python -m sample_data_gen.render_cli OUT``: render checkerboard image sequences of a
synthetic two-camera ACS with their ground truth (see :mod:`sample_data_gen.render`).

Without ``--scenario`` all three scenarios are written (``OUT/overlap``,
``OUT/fixed_joint``, ``OUT/general``); with it, only ``OUT/<scenario>``. The issue's accuracy
configuration is ``--size 1024x768 --frames 20 --board-distance 0.75 --joint-distance 0.25``.
``--target aprilgrid`` (or ``charuco``, or any ``acscal --target`` value: a short form or a
target YAML) films that target instead of the checkerboard, and writes ``target.yaml``.
``--video mkv`` (or ``avi``, ``mp4``) also writes each camera's images as a video,
``<scenario>/cam_a.mkv``, at ``--video-fps`` frames per second (see
:mod:`sample_data_gen.video`).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from acs_cli.core.targets import AprilGrid, Charuco
from acs_cli.errors import AcsError
from acs_cli.io.target import parse_target
from sample_data_gen.render import RENDER_SCENARIOS, SCENE_TARGETS, render_scenario


def _pair(text: str, what: str) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must look like 640x480, got {text!r}") from None
    if a < 1 or b < 1:
        raise argparse.ArgumentTypeError(f"{what} must be positive, got {text!r}")
    return a, b


def _target(text: str) -> AprilGrid | Charuco:
    """``--target``: a name of :data:`SCENE_TARGETS`, or an AprilGrid or ChArUco as acscal
    reads it (short form or target YAML)."""
    if text in SCENE_TARGETS:
        return SCENE_TARGETS[text]
    try:
        target = parse_target(text)
    except AcsError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not isinstance(target, AprilGrid | Charuco):
        raise argparse.ArgumentTypeError("--target must be an AprilGrid or a ChArUco (use --board)")
    return target


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m sample_data_gen.render_cli",
        description="Render checkerboard image sequences of a synthetic articulated camera "
        "system (two cameras) and write truth.yaml beside them.",
    )
    p.add_argument("out_dir", metavar="OUT", help="folder to write into (created)")
    p.add_argument("--scenario", choices=RENDER_SCENARIOS, help="one scenario (default: all)")
    p.add_argument(
        "--size",
        type=lambda s: _pair(s, "--size"),
        default=(640, 480),
        metavar="WxH",
        help="image size (default 640x480)",
    )
    p.add_argument("--frames", type=int, default=20, help="images per camera (default 20)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--board",
        type=lambda s: _pair(s, "--board"),
        default=(9, 6),
        metavar="COLSxROWS",
        help="inner corners (default 9x6)",
    )
    p.add_argument("--square", type=float, default=0.025, metavar="M", help="square size, m")
    p.add_argument(
        "--board-distance", type=float, default=0.6, metavar="M", help="camera to board, m"
    )
    p.add_argument(
        "--joint-distance", type=float, default=0.25, metavar="M", help="|o_a|, |o_b|, m"
    )
    p.add_argument("--no-blur", action="store_true", help="no Gaussian blur")
    p.add_argument(
        "--noise", type=float, default=2.0, metavar="SIGMA", help="sensor noise, grey levels"
    )
    p.add_argument(
        "--partial", type=float, default=0.1, metavar="FRAC", help="fraction of partial views"
    )
    p.add_argument(
        "--missing", type=float, default=0.05, metavar="FRAC", help="fraction without the board"
    )
    p.add_argument("--supersample", type=int, default=2, metavar="S", help="S x S samples a pixel")
    p.add_argument(
        "--target",
        type=_target,
        default=None,
        metavar="TARGET",
        help="film a target instead of the checkerboard: aprilgrid (4x3 tags of 0.045 m), "
        "charuco (7x5 squares of 0.035 m) or an acscal --target value (aprilgrid:4x3:0.045:0.3, "
        "a target YAML); writes target.yaml beside truth.yaml",
    )
    p.add_argument(
        "--video",
        choices=("mkv", "avi", "mp4"),
        default=None,
        help="also write each camera's images as <scenario>/cam_<x>.<suffix>: FFV1 (mkv, "
        "lossless), MJPEG (avi) or H.264 (mp4)",
    )
    p.add_argument(
        "--video-fps", type=float, default=10.0, metavar="FPS", help="the videos' frame rate"
    )
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.frames < 1:
        parser.error("--frames must be at least 1")
    scenarios = [args.scenario] if args.scenario else list(RENDER_SCENARIOS)
    for sc in scenarios:
        t0 = time.perf_counter()
        try:
            path = render_scenario(
                args.out_dir,
                sc,
                seed=args.seed,
                frames=args.frames,
                size=args.size,
                board=args.board,
                square=args.square,
                board_distance=args.board_distance,
                joint_distance=args.joint_distance,
                blur=not args.no_blur,
                noise_sigma=args.noise,
                partial_fraction=args.partial,
                missing_fraction=args.missing,
                supersample=args.supersample,
                target=args.target,
            )
        except (ValueError, RuntimeError) as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        if args.video is not None:
            from sample_data_gen.video import folder_to_video

            for cam in ("cam_a", "cam_b"):
                folder_to_video(path / cam, path / f"{cam}.{args.video}", fps=args.video_fps)
        print(f"{sc}: {path} ({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
