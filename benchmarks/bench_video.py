"""Video input: speed against a PNG folder, and memory against the recording's length.

Issue 21's two figures, each from real ``acscal`` processes on rendered 1920x1080 frames:

1. **Speed.** ``acscal poses`` on the same frames as a PNG folder and as an H.264 ``.mp4``
   (``sample_data_gen.video.write_video``), each with an empty detections cache, best of
   ``--repeats`` runs: frames per second of the whole command, and their ratio (aim: the
   video at least 0.8x the folder).
2. **Memory.** ``acscal poses`` on a 1-minute and a 10-minute H.264 video at ``--fps`` (the
   frames of a short render looped, so that the long video costs encoding time only): the
   peak resident memory of the command (``ru_maxrss``, the largest of its processes), which
   must not grow with the length (aim: the 10-minute one within a small margin of the
   1-minute one). Three settings, each run on both videos:

   - ``--every K --workers 1``: the kept frames grow with the length (12 and 120 at the
     defaults), one process holds everything;
   - ``--max-frames M --workers 1``: the same kept frames from both lengths;
   - ``--max-frames M`` with the default workers: the same, detected in a pool;
   - ``--every K`` with the default workers: the short video's 12 frames run in the
     command's process, the long one's 120 in a pool (more than
     ``acs_cli.stages.intrinsics.MIN_IMAGES_PER_WORKER`` frames), whose worker, forked from
     the command, counts its parent's pages in its own resident memory: this compares a
     process with a pool's worker, not two lengths.

Run: ``PYTHONPATH=. .venv/bin/python benchmarks/bench_video.py`` (about 30 min on the
project's 2-core machine, most of it encoding the long video; ``--work DIR`` keeps the
videos there and reuses them; ``--quick`` for a smaller check).
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from sample_data_gen.render import render_scenario
from sample_data_gen.video import write_video

ACSCAL = Path(sys.executable).with_name("acscal")


def _run(*args: str | Path) -> float:
    """Wall seconds of one ``acscal`` command."""
    t0 = time.perf_counter()
    res = subprocess.run([str(ACSCAL), *map(str, args)], capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if res.returncode != 0:
        raise SystemExit(f"acscal {' '.join(map(str, args))} failed:\n{res.stderr}")
    return seconds


def _peak(*args: str | Path) -> int:
    """Peak resident memory (KiB) of one ``acscal`` command, measured alone."""
    code = (
        "import resource, subprocess, sys;"
        "subprocess.run(sys.argv[1:], check=True, capture_output=True);"
        "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, str(ACSCAL), *map(str, args)],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(out.stdout.strip())


def _speed(work: Path, folder: Path, mp4: Path, intr: Path, n: int, repeats: int) -> None:
    """``acscal poses`` on the folder and on the video, best of ``repeats``, interleaved."""
    print(f"speed: acscal poses on {n} frames of 1920x1080 (best of {repeats})")
    runs: dict[str, list[float]] = {"PNG folder": [], "H.264 video": []}
    for r in range(repeats):
        for name, src in (("PNG folder", folder), ("H.264 video", mp4)):
            out = work / f"poses_{name[:3]}_{r}" / "poses.npz"
            runs[name].append(_run("poses", src, "--intrinsics", intr, "-o", out))
    best = {name: min(v) for name, v in runs.items()}
    for name, seconds in best.items():
        print(f"  {name:12s} {seconds:6.2f} s  {n / seconds:6.2f} frames/s")
    ratio = best["PNG folder"] / best["H.264 video"]
    print(f"  video/folder frames per second: {ratio:.2f} (aim >= 0.8)")


def _frames(folder: Path) -> list[np.ndarray]:
    return [
        np.asarray(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)) for p in sorted(folder.glob("*.png"))
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60, help="frames of the speed test")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--fps", type=float, default=10.0, help="frame rate of the memory videos")
    ap.add_argument("--every", type=int, default=50, help="--every of the memory runs")
    ap.add_argument("--max-frames", type=int, default=120, help="--max-frames of the memory runs")
    ap.add_argument("--work", type=Path, help="work folder, kept (its videos reused)")
    ap.add_argument("--quick", action="store_true", help="30 frames, 1 and 3 minutes")
    ap.add_argument("--part", choices=("speed", "memory", "both"), default="both")
    args = ap.parse_args(argv)
    n_frames, long_min = (30, 3) if args.quick else (args.frames, 10)
    work = args.work or Path(tempfile.mkdtemp(prefix="bench_video_"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        scene = render_scenario(
            work / "render", "fixed_joint", seed=5, frames=n_frames, size=(1920, 1080),
            board_distance=0.6, supersample=1,
        )  # fmt: skip
        folder = scene / "cam_a"
        frames = _frames(folder)
        times = [i / args.fps for i in range(len(frames))]
        mp4 = write_video(work / "cam_a.mp4", frames, times)
        _run("intrinsics", folder, "-o", work / "calib" / "intrinsics.yaml")
        # alone in its folder: `poses` would reuse the detections cache beside it
        intr = work / "intrinsics.yaml"
        shutil.copyfile(work / "calib" / "intrinsics.yaml", intr)

        if args.part != "memory":
            _speed(work, folder, mp4, intr, len(frames), args.repeats)
        if args.part == "speed":
            return 0
        print(f"memory: acscal poses on H.264 1080p at {args.fps:g} fps, peak resident memory")
        settings = {
            f"--every {args.every} --workers 1": ["--every", str(args.every), "--workers", "1"],
            f"--max-frames {args.max_frames} --workers 1": [
                "--max-frames", str(args.max_frames), "--workers", "1",
            ],
            f"--max-frames {args.max_frames} (default workers)": [
                "--max-frames", str(args.max_frames),
            ],
            f"--every {args.every} (default workers)": ["--every", str(args.every)],
        }  # fmt: skip
        peaks: dict[str, dict[int, int]] = {k: {} for k in settings}
        for minutes in (1, long_min):
            n = round(60 * minutes * args.fps)
            video = work / f"long_{minutes}.mp4"
            if not video.is_file():
                looped = (frames[i % len(frames)] for i in range(n))
                write_video(video, looped, [i / args.fps for i in range(n)])
            for name, extra in settings.items():
                out = work / f"mem_{minutes}" / "poses.npz"
                shutil.rmtree(out.parent, ignore_errors=True)
                peaks[name][minutes] = _peak(
                    "poses", video, "--intrinsics", intr, "-o", out, *extra
                )
        print(f"  | setting | 1 min ({round(60 * args.fps)} frames) | {long_min} min "
              f"({round(60 * long_min * args.fps)} frames) | ratio |")  # fmt: skip
        print("  | --- | --- | --- | --- |")
        for name, p in peaks.items():
            print(f"  | `{name}` | {p[1] / 1024:.1f} MiB | {p[long_min] / 1024:.1f} MiB | "
                  f"{p[long_min] / p[1]:.3f} |")  # fmt: skip
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
