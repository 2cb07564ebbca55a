"""``acscal trajectory --rig`` on long recordings (issue 22): wall clock, peak memory, and where
the time goes.

The sample five-camera rig (:data:`sample_data_gen.rig_sim.SAMPLE_JOINTS`: rigid ``r01``,
ball ``j02``, hinge ``j23``, rigid ``r34``; ``cam4`` of unknown scale; the sample's pose noise
:data:`sample_data_gen.writer.RIG_NOISE`) moving smoothly (``rig_recording(...,
smooth=True)``) at 30 fps. One recording of the longest length is simulated and written as
TUM files, and its prefixes as recordings of every ``--frames`` length: one session, so each
camera keeps its trajectory's world, which ``rig.yaml``'s ``T_ref_world`` maps. Then:

1. ``acscal run config.yaml`` calibrates the rig on the first ``--calib-frames`` frames
   (default 600: 20 s, what a user calibrates on), as ``python -m sample_data_gen OUT --rig``
   configures it.
2. ``acscal trajectory --rig calib/out/rig.yaml --poses cam0=rec_N/cam0.tum ... -o
   traj_N/`` maps each recording (default 1,000, 10,000 and 100,000 frames): every camera's
   and joint's TUM file and ``angles.csv``. Each run is a fresh process of this tree's
   ``acs_cli`` (``python -P -c`` with ``PYTHONPATH``, as ``bench_startup.py``), started by a
   small Python process of its own that times it (``time.perf_counter`` around
   ``subprocess.run``) and reads its peak resident memory (``resource.getrusage`` of its
   children: ``ru_maxrss``; from this process, a forked child would count the memory it
   starts with, this process's). Best and median of ``--repeat`` runs; each run's outputs
   are compared with the first's, byte for byte.
3. The same call for the longest recording in this process under ``cProfile``: the parts of
   the command (reading, mapping, writing) and the functions with the most own time.

A sanity column checks the outputs against the truth: the RMS position error of each camera's
mapped trajectory (the reference camera's frame at frame 0, metres), the worst camera's. With
``--compare-tree DIR`` the longest recording is also mapped by another source tree's
``acs_cli`` (e.g. the main branch's, before a change) and by this one, the two interleaved
round by round (a load on the machine falls on both alike): their times, and whether their
outputs are byte for byte the same.

    .venv/bin/python benchmarks/bench_trajectory_scale.py                 # ~1.5 min here
    .venv/bin/python benchmarks/bench_trajectory_scale.py --frames 1000 10000 --repeat 1
    .venv/bin/python benchmarks/bench_trajectory_scale.py --compare-tree /work/main  # ~2.5 min

Work files go under ``--work`` (default ``/tmp/acscal_bench_traj``), never into the repository.
Markdown tables on stdout, progress on stderr.
"""

# ruff: noqa: E402  (BLAS threads must be set before numpy is imported)
from __future__ import annotations

import os

# as the acscal command does (acs_cli/cli/__init__.py): one BLAS thread unless told otherwise
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse
import contextlib
import cProfile
import filecmp
import io
import platform
import pstats
import shutil
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from acs_cli.core import se3
from acs_cli.io.trajectory import read_trajectory, write_tum
from sample_data_gen.rig_sim import RigRecording, rig_recording
from sample_data_gen.writer import RIG_NOISE, rig_config_text

HERE = Path(__file__).resolve().parents[1]
FPS = 30.0
UNKNOWN_SCALE = ("cam4",)
#: Runs acscal's entry point as the console script does, from the tree on PYTHONPATH.
_MAIN = "import sys, acs_cli.cli.main as m; sys.argv[0] = 'acscal'; m.main()"
#: The parts of the command in the profile: (label, function name as pstats shows it).
PARTS = (
    ("read rig.yaml", "load"),
    ("read the trajectories", "read_trajectory"),
    ("map them (trajectories_from_rig)", "trajectories_from_rig"),
    ("write the TUM files", "write_tum"),
    ("joint angles (rig_angles)", "rig_angles"),
    ("write angles.csv", "write_angles_csv"),
)


def log(text: str) -> None:
    print(text, file=sys.stderr, flush=True)


def table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def machine_info() -> str:
    threads = os.environ.get("OPENBLAS_NUM_THREADS", "default")
    load = "{:.2f} {:.2f} {:.2f}".format(*os.getloadavg())
    return (
        f"{platform.platform()}, Python {platform.python_version()}, numpy {np.__version__}, "
        f"{os.cpu_count()} CPUs, OPENBLAS_NUM_THREADS={threads}, load average {load}"
    )


# --------------------------------------------------------------------------- the data


def write_recording(rec: RigRecording, folder: Path, n: int) -> None:
    """The first ``n`` frames of every camera's trajectory file, ``<camera>.tum``."""
    folder.mkdir(parents=True, exist_ok=True)
    for c in rec.topology.cameras:
        write_tum(folder / f"{c}.tum", rec.timestamps[:n], rec.T_wc_c[c][:n])


def write_config(rec: RigRecording, folder: Path) -> Path:
    """``config.yaml`` of the recording in ``folder``, as ``python -m sample_data_gen OUT
    --rig`` writes it."""
    path = folder / "config.yaml"
    path.write_text(rig_config_text(rec), encoding="utf-8")
    return path


# --------------------------------------------------------------------------- the runs


def acscal_argv(*args: str | Path) -> list[str]:
    return [sys.executable, "-P", "-c", _MAIN, *map(str, args)]


#: Runs one command (argv[2:]) with its output to the file argv[1] and prints its wall
#: seconds and peak resident memory: a small process of its own, so that the child's
#: ``ru_maxrss`` is not this process's memory, which a forked child starts with.
_MEASURE = """
import resource, subprocess, sys, time
with open(sys.argv[1], "w") as log:
    t0 = time.perf_counter()
    code = subprocess.run(sys.argv[2:], stdout=log, stderr=subprocess.STDOUT).returncode
    seconds = time.perf_counter() - t0
print(seconds, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, code)
"""


def run_child(argv: Sequence[str], tree: Path, logfile: Path) -> tuple[float, float]:
    """Wall seconds and peak resident memory (MiB) of one fresh process; it must succeed."""
    env = dict(os.environ, PYTHONPATH=str(tree), COLUMNS="100")
    res = subprocess.run(
        [sys.executable, "-c", _MEASURE, str(logfile), *argv],
        env=env,
        check=True,
        capture_output=True,
        text=True,
    )
    seconds, kib, code = res.stdout.split()
    if int(code) != 0:
        raise SystemExit(f"{' '.join(argv[4:])} failed ({code}); see {logfile}")
    return float(seconds), int(kib) / 1024.0  # ru_maxrss: KiB on Linux


def trajectory_args(rig_file: Path, rec_dir: Path, cams: Sequence[str], out: Path) -> list[str]:
    args: list[str] = ["trajectory", "--rig", str(rig_file)]
    for c in cams:
        args += ["--poses", f"{c}={rec_dir / f'{c}.tum'}"]
    return [*args, "-o", str(out)]


def same_outputs(a: Path, b: Path) -> bool:
    """Whether the folders hold the same files, byte for byte."""
    names = sorted(p.name for p in a.iterdir())
    if names != sorted(p.name for p in b.iterdir()):
        return False
    return all(filecmp.cmp(a / n, b / n, shallow=False) for n in names)


def position_error(rec: RigRecording, out: Path, n: int) -> float:
    """The worst camera's RMS position error (m) of ``out``'s trajectories against the truth
    (the reference camera's frame at frame 0; the reference camera is metric)."""
    T_ref0 = se3.invert_transforms(rec.T_W_c[rec.topology.reference][0])
    worst = 0.0
    for c in rec.topology.cameras:
        got = read_trajectory(out / f"{c}.tum").T_world_cam[:, :3, 3]
        true = (T_ref0 @ rec.T_W_c[c][:n])[:, :3, 3]
        worst = max(worst, float(np.sqrt(np.mean(np.sum((got - true) ** 2, axis=1)))))
    return worst


def profile(argv: list[str], top: int) -> tuple[str, str]:
    """The command's parts and its functions with the most own time, in this process."""
    import acs_cli.cli.main as cli

    prof = cProfile.Profile()
    t0 = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):  # the command's own summary
        prof.enable()
        try:
            cli.main(argv)
        except SystemExit as exc:
            if exc.code:
                raise
        prof.disable()
    total = time.perf_counter() - t0
    stats = pstats.Stats(prof, stream=io.StringIO())
    raw = stats.stats  # type: ignore[attr-defined]
    rows = []
    for label, func in PARTS:
        hits = [(v[1], v[3]) for k, v in raw.items() if k[2] == func and "acs_cli" in k[0]]
        calls, cum = sum(h[0] for h in hits), sum(h[1] for h in hits)
        rows.append([label, str(calls), f"{cum:.2f}", f"{100 * cum / total:.0f} %"])
    accounted = sum(float(r[2]) for r in rows)
    rows.append(["the rest (imports, typer, checks)", "", f"{total - accounted:.2f}", ""])
    rows.append(["**total (under cProfile)**", "", f"**{total:.2f}**", ""])
    parts = table(["part", "calls", "cumulative s", "share"], rows)
    own = sorted(raw.items(), key=lambda kv: kv[1][2], reverse=True)[:top]
    frows = []
    for (file, line, func), (_cc, nc, tt, ct, _callers) in own:
        where = file if file.startswith("~") else f"{_short(file)}:{line}"
        frows.append([f"`{func}`", where, str(nc), f"{tt:.2f}", f"{ct:.2f}"])
    funcs = table(["function", "where", "calls", "own s", "cumulative s"], frows)
    return parts, funcs


def compare(
    tree: Path, work: Path, rig_file: Path, cams: Sequence[str], n: int, rounds: int
) -> str:
    """This tree's and ``tree``'s ``acscal trajectory --rig`` on ``n`` frames, interleaved
    round by round (a load on the machine falls on both alike), and whether their outputs
    are byte for byte the same."""
    trees = {"this": HERE, "other": tree}
    times: dict[str, list[float]] = {k: [] for k in trees}
    peaks: dict[str, list[float]] = {k: [] for k in trees}
    for r in range(rounds):
        for k, root in trees.items():
            out = work / f"traj_{n}_cmp_{k}"
            cmd = acscal_argv(*trajectory_args(rig_file, work / f"rec_{n}", cams, out))
            s, mb = run_child(cmd, root, work / f"compare_{k}_{r}.log")
            times[k].append(s)
            peaks[k].append(mb)
            log(f"  {root}, {n} frames, round {r + 1}: {s:.2f} s, {mb:.0f} MiB")
    same = same_outputs(work / f"traj_{n}_cmp_this", work / f"traj_{n}_cmp_other")
    rows = [
        [f"`{root}`" + (" (this)" if k == "this" else ""), f"{n:,}", f"{min(times[k]):.2f}",
         f"{statistics.median(times[k]):.2f}", f"{max(peaks[k]):.0f}"]
        for k, root in trees.items()
    ]  # fmt: skip
    verdict = "byte for byte the same" if same else "**not the same**"
    head = ["tree", "frames", "best s", "median s", "peak RSS MiB"]
    return f"Against another tree, {rounds} interleaved rounds; outputs {verdict}:\n\n" + table(
        head, rows
    )


def _short(file: str) -> str:
    for marker in ("acs_cli/", "site-packages/", "lib/python"):
        i = file.find(marker)
        if i >= 0:
            return file[i:]
    return file


# --------------------------------------------------------------------------- main


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, nargs="+", default=[1_000, 10_000, 100_000])
    ap.add_argument("--calib-frames", type=int, default=600, help="frames acscal run uses")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each trajectory command")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--work", type=Path, default=Path("/tmp/acscal_bench_traj"))
    ap.add_argument("--top", type=int, default=12, help="functions listed from the profile")
    ap.add_argument("--no-profile", action="store_true", help="skip the cProfile part")
    ap.add_argument(
        "--compare-tree",
        type=Path,
        help="another source tree holding acs_cli/ (e.g. the main branch's): time it on the "
        "longest recording too and compare its outputs byte for byte",
    )
    args = ap.parse_args(argv)
    work: Path = args.work.resolve()
    if work == HERE or HERE in work.parents:
        ap.error("--work must be outside the repository")
    frames = sorted(set(args.frames))
    longest = max(max(frames), args.calib_frames)
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)

    log(f"simulating {longest} frames of the sample rig (smooth, {FPS:g} fps) ...")
    rec = rig_recording(
        np.random.default_rng([args.seed, 2]),
        longest,
        unknown_scale=UNKNOWN_SCALE,
        sigma_rot_deg=RIG_NOISE[0],
        sigma_trans=RIG_NOISE[1],
        smooth=True,
        fps=FPS,
    )
    cams = list(rec.topology.cameras)
    calib = work / "calib"
    write_recording(rec, calib, args.calib_frames)
    config = write_config(rec, calib)
    for n in frames:
        write_recording(rec, work / f"rec_{n}", n)

    log(f"acscal run on {args.calib_frames} frames ...")
    calib_s, calib_mb = run_child(acscal_argv("run", config), HERE, work / "calib.log")
    rig_file = calib / "out" / "rig.yaml"
    log(f"  {calib_s:.1f} s")

    rows = []
    results: dict[int, tuple[list[float], list[float]]] = {}
    for n in frames:
        rec_dir, out = work / f"rec_{n}", work / f"traj_{n}"
        times, peaks = [], []
        for k in range(args.repeat):
            target = out if k == 0 else work / f"traj_{n}_again"
            cmd = acscal_argv(*trajectory_args(rig_file, rec_dir, cams, target))
            s, mb = run_child(cmd, HERE, work / f"traj_{n}_{k}.log")
            times.append(s)
            peaks.append(mb)
            if k and not same_outputs(out, target):
                raise SystemExit(f"run {k + 1} on {n} frames wrote other outputs than the first")
            log(f"  {n} frames, run {k + 1}: {s:.2f} s, {mb:.0f} MiB")
        results[n] = (times, peaks)
        size = sum(p.stat().st_size for p in rec_dir.iterdir()) / 2**20
        err = position_error(rec, out, n)
        best = min(times)
        rows.append(
            [
                f"{n:,}",
                f"{size:.1f}",
                f"{best:.2f}",
                f"{statistics.median(times):.2f}",
                f"{1e6 * best / n:.0f}",
                f"{max(peaks):.0f}",
                f"{100 * err:.2f}",
            ]
        )

    print("## acscal trajectory --rig on long recordings")
    print()
    print(machine_info())
    print()
    print(
        f"Calibration: `acscal run` on {args.calib_frames} frames ({args.calib_frames / FPS:g} "
        f"s at {FPS:g} fps): {calib_s:.1f} s, peak {calib_mb:.0f} MiB. Trajectory runs: best "
        f"and median of {args.repeat}, fresh processes."
    )
    print()
    print(
        table(
            [
                "frames",
                "input MiB (5 TUM)",
                "best s",
                "median s",
                "us/frame",
                "peak RSS MiB",
                "worst camera RMS position error (cm)",
            ],
            rows,
        )
    )

    if args.compare_tree is not None:
        print()
        print(compare(args.compare_tree.resolve(), work, rig_file, cams, max(frames), args.repeat))

    if not args.no_profile:
        n = max(frames)
        log(f"profiling {n} frames in-process ...")
        cmd = trajectory_args(rig_file, work / f"rec_{n}", cams, work / f"traj_{n}_profile")
        parts, funcs = profile(cmd, args.top)
        if not same_outputs(work / f"traj_{n}", work / f"traj_{n}_profile"):
            raise SystemExit("the profiled run wrote other outputs")
        print()
        print(f"Where the time goes, {n:,} frames (cProfile, in-process):")
        print()
        print(parts)
        print()
        print(funcs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
