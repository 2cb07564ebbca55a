"""``acscal --help`` starts fast because it imports little (issue 12).

What a fresh interpreter has imported after the CLI's help is the property that keeps the
start-up within 2x ``python -c "import numpy"``; the timings themselves are in
``benchmarks/bench_startup.py``.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

#: Modules the help and the version must not import (each costs 20 ms to seconds).
HEAVY = (
    "numpy",
    "scipy",
    "cv2",
    "pycolmap",
    "yaml",
    "matplotlib",
    "pydantic",
    "typer.rich_utils",
    "rich.console",
    "rich.table",
    "rich.progress",
    "acs_cli.core",
    "acs_cli.io",
    "acs_cli.stages",
)

SCRIPT = """
import contextlib, io, json, sys
import acs_cli.cli.main as m
for args in {argvs!r}:
    with contextlib.redirect_stdout(io.StringIO()):
        try:
            m.main(args)
        except SystemExit:
            pass
print(json.dumps(sorted(k for k in sys.modules if k in {heavy!r})))
"""


def imported_after(*argvs: list[str]) -> list[str]:
    """The modules of :data:`HEAVY` a fresh interpreter holds after ``acscal ARGV...``."""
    code = SCRIPT.format(argvs=list(argvs), heavy=set(HEAVY))
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_importing_the_cli_imports_nothing_heavy() -> None:
    assert imported_after() == []


@pytest.mark.parametrize(
    "argv", [["--help"], ["joint", "--help"], ["run", "--help"], ["--version"]]
)
def test_help_and_version_import_nothing_heavy(argv: list[str]) -> None:
    assert imported_after(argv) == []


def test_the_version_needs_no_package_metadata() -> None:
    """``acs_cli.__version__`` is written in ``acs_cli/_version.py`` (``pyproject.toml`` reads
    it), not read through :mod:`importlib.metadata` (10-20 ms of every artifact's writing);
    the installed package's metadata says the same."""
    from importlib.metadata import version

    code = "import sys, acs_cli; print('importlib.metadata' in sys.modules, acs_cli.__version__)"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    loaded, ours = res.stdout.split()
    assert loaded == "False" and ours == version("acscal")


def test_options_are_read_without_pydantic() -> None:
    """Typer would build a pydantic adapter per option (0.15-0.2 s of a command's start):
    acscal's options are plain and coerced without it (:mod:`acs_cli.cli.coercion`)."""
    argv = ["intrinsics", "missing_dir", "-o", "x.yaml", "--board", "9x6", "--square", "0.02",
            "--workers", "2", "--model", "rational", "--every", "2", "--export", "ros",
            "--camera-name", "left"]  # fmt: skip
    heavy = {"pydantic", "rich.console", "rich.progress", "acs_cli.stages"}
    code = SCRIPT.format(argvs=[argv], heavy=heavy)
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert "no such folder" in res.stderr  # read the options, then ran
    # stderr is a pipe here: no progress bar, and its one line needs no rich at all
    assert json.loads(res.stdout.strip().splitlines()[-1]) == ["acs_cli.stages"]


def test_a_command_that_runs_does_import_its_stage() -> None:
    """The guard above is not vacuous: running a command loads what it needs."""
    assert "acs_cli.stages" in imported_after(["joint", "--poses-a", "missing.tum", "-o", "x"])


def test_a_solving_command_leaves_scipy_s_heavy_packages_alone(tmp_path: Path) -> None:
    """A whole ``joint --overlap`` (engine, outlier test, correlated-error test, writing)
    needs none of scipy.stats, scipy.spatial, scipy.optimize or scipy.interpolate: together
    about 1.5 s of every command's start (only clock estimation imports them)."""
    from acs_cli.io.trajectory import write_tum
    from sample_data_gen.acs_sim import near_hinge_pair

    p = near_hinge_pair(np.random.default_rng(3), 40, wobble_deg=15.0)
    a, b = tmp_path / "a.tum", tmp_path / "b.tum"
    write_tum(a, p.timestamps, p.T_w_a)
    write_tum(b, p.timestamps, p.T_w_b)
    code = SCRIPT.format(
        argvs=[["joint", "--overlap", "--poses-a", str(a), "--poses-b", str(b),
                "-o", str(tmp_path / "j.yaml")]],
        heavy={"scipy.stats", "scipy.spatial", "scipy.optimize", "scipy.interpolate",
               "acs_cli.stages"},
    )  # fmt: skip
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "j.yaml").is_file(), res.stderr
    assert json.loads(res.stdout.strip().splitlines()[-1]) == ["acs_cli.stages"]


def test_a_terminal_gets_the_progress_bar(monkeypatch: pytest.MonkeyPatch) -> None:
    from rich.progress import Progress

    from acs_cli.cli import images

    monkeypatch.setattr(images.err.rich, "_force_terminal", False)
    assert isinstance(images._bar(), images._NoBar)
    monkeypatch.setattr(images.err.rich, "_force_terminal", True)
    assert isinstance(images._bar(), Progress)


def test_the_console_script_freezes_its_objects_for_a_fast_exit() -> None:
    """``main()`` as the console script (no argv) ends its process: its objects are frozen
    out of the collector, which the interpreter's exit would otherwise walk (0.08-0.1 s);
    called with an argv (a caller that goes on), nothing is frozen."""
    code = (
        "import gc, sys\n"
        "from acs_cli.cli.main import main\n"
        "sys.argv = ['acscal', '--version']\n"
        "for args in ([], None):\n"
        "    try:\n"
        "        main(['--version'] if args == [] else None)\n"
        "    except SystemExit:\n"
        "        pass\n"
        "    print(gc.get_freeze_count() > 0)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert [w for w in res.stdout.split() if w in ("False", "True")] == ["False", "True"]
