"""Start-up time of the ``acscal`` command line (issue 12): help and version against numpy.

Each command is run as a user runs it (a new process, the installed console script) several
times, the commands interleaved round by round so that a load on the machine falls on all
of them alike; the median of each is compared with a bare ``python -c "import numpy"``
(the floor of any tool that computes with numpy). The issue's target: ``acscal --help``
and small commands within 2x that baseline.

Printed (Markdown): median and minimum seconds of each command and the median's ratio to
the baseline's.

    .venv/bin/python benchmarks/bench_startup.py             # 15 rounds, ~30 s here
    .venv/bin/python benchmarks/bench_startup.py --rounds 3  # a smoke run

``--tree DIR`` also times the help of another source tree's ``acs_cli`` (a folder holding
``acs_cli/``, e.g. ``git archive HEAD acs_cli | tar -x -C DIR``), run as ``python -P -c``
with ``PYTHONPATH=DIR`` (``-P``: not the working folder's ``acs_cli``), beside this tree's
run the same way: a before/after comparison.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

ACSCAL = str(Path(sys.executable).with_name("acscal"))

#: (label, argv) of every command timed; the first is the baseline.
COMMANDS: tuple[tuple[str, list[str]], ...] = (
    ('python -c "import numpy"', [sys.executable, "-c", "import numpy"]),
    ("acscal --help", [ACSCAL, "--help"]),
    ("acscal joint --help", [ACSCAL, "joint", "--help"]),
    ("acscal --version", [ACSCAL, "--version"]),
)


_MAIN = "import sys, acs_cli.cli.main as m; sys.argv[0] = 'acscal'; m.main()"


def tree_commands(tree: Path, label: str) -> list[tuple[str, list[str], dict[str, str]]]:
    """``--help`` and ``joint --help`` of the ``acs_cli`` in ``tree``, as ``python -c``."""
    env = {"PYTHONPATH": str(tree)}
    return [
        (
            f"{label}: acscal{' ' + ' '.join(a) if a else ''} --help",
            [sys.executable, "-P", "-c", _MAIN, *a, "--help"],
            env,
        )
        for a in ([], ["joint"])
    ]


def time_once(argv: Sequence[str], extra_env: dict[str, str] | None = None) -> float:
    """Wall-clock seconds of one run of ``argv`` (output discarded; it must succeed)."""
    env = dict(os.environ, COLUMNS="80", **(extra_env or {}))
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, env=env)
    return time.perf_counter() - t0


def measure(
    commands: Sequence[tuple[str, list[str], dict[str, str]]], rounds: int
) -> dict[str, list[float]]:
    """``rounds`` timings of every command, interleaved round by round (the first, the
    baseline, included)."""
    for _, argv, env in commands:  # warm the file cache (and .pyc files) first
        time_once(argv, env)
    times: dict[str, list[float]] = {label: [] for label, _, _ in commands}
    for _ in range(rounds):
        for label, argv, env in commands:
            times[label].append(time_once(argv, env))
    return times


def table(times: dict[str, list[float]]) -> str:
    """The Markdown table of medians, minima and ratios to the baseline's (the first row)."""
    base = statistics.median(next(iter(times.values())))
    lines = [
        "| command | median s | min s | median / numpy |",
        "|---|---|---|---|",
    ]
    for label in times:
        med = statistics.median(times[label])
        lines.append(f"| `{label}` | {med:.3f} | {min(times[label]):.3f} | {med / base:.2f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=15, help="runs of each command")
    parser.add_argument("--tree", type=Path, help="another tree's acs_cli to compare with")
    args = parser.parse_args(argv)
    commands: list[tuple[str, list[str], dict[str, str]]] = [
        (label, list(cmd), {}) for label, cmd in COMMANDS
    ]
    if args.tree is not None:
        here = Path(__file__).resolve().parents[1]
        commands += tree_commands(args.tree, str(args.tree)) + tree_commands(here, "this tree")
    times = measure(commands, args.rounds)
    print(f"{args.rounds} rounds, interleaved; {os.cpu_count()} CPUs, load {os.getloadavg()}")
    print()
    print(table(times))


if __name__ == "__main__":
    main()
