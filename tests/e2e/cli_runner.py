"""Running ``acscal`` as a user would (shared by the e2e tests).

Each call is a process of its own with the user's environment (a clean warnings filter,
default signal handlers, ``COLUMNS``/``NO_COLOR`` set, stdin empty, stdout and stderr
captured), its exit status the command's. By default the process is a fork of the test
worker with the CLI already imported (:func:`_forked`): the console script's own code path
(:func:`acs_cli.cli.main.main`) without paying 0.5-1 s of imports (numpy, OpenCV, SciPy,
Rich) on each of the suite's hundreds of commands. ``ACSCAL_E2E_EXEC=1`` runs the
installed console script instead, as do calls that need the real executable (a
``preexec_fn``); ``test_cli_help`` and the kill tests of ``test_faults`` always do.
"""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path

ACSCAL = Path(sys.executable).with_name("acscal")

#: the e2e commands run the installed console script (not a fork of the test worker)
EXEC = os.environ.get("ACSCAL_E2E_EXEC", "") == "1" or not hasattr(os, "fork")

#: what a command's environment adds (wide, uncoloured output)
ENV = {"COLUMNS": "200", "NO_COLOR": "1"}

#: a fresh interpreter's warnings filters (CPython 3.11, no -W or PYTHONWARNINGS)
_DEFAULT_FILTERS = (
    ("default", DeprecationWarning, "__main__"),
    ("ignore", DeprecationWarning, ""),
    ("ignore", PendingDeprecationWarning, ""),
    ("ignore", ImportWarning, ""),
    ("ignore", ResourceWarning, ""),
)


def acscal(
    *args: str | Path,
    cwd: Path | None = None,
    timeout: float | None = 300,
    preexec_fn: Callable[[], None] | None = None,
) -> subprocess.CompletedProcess[str]:
    """Run ``acscal ARGS`` and return the finished process (``preexec_fn`` runs in the
    child before ``acscal`` starts, e.g. to set a limit; such calls exec the script)."""
    argv = [str(a) for a in args]
    if EXEC or preexec_fn is not None:
        return subprocess.run(
            [str(ACSCAL), *argv],
            capture_output=True,
            text=True,
            cwd=cwd,
            env=dict(os.environ, **ENV),
            timeout=timeout,
            preexec_fn=preexec_fn,
        )
    return _forked(argv, cwd, timeout)


def _forked(
    argv: list[str], cwd: Path | None, timeout: float | None
) -> subprocess.CompletedProcess[str]:
    """``acscal ARGV`` in a fork of this process (module doc)."""
    import cv2

    from acs_cli.cli import main as cli

    with tempfile.TemporaryFile() as fout, tempfile.TemporaryFile() as ferr:
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child
            cv2.setNumThreads(-1)  # OpenCV's default, as a fresh process (tests/conftest.py)
            _child(cli.main, argv, cwd, fout.fileno(), ferr.fileno())
        status = _wait(pid, timeout, argv)
        fout.seek(0)
        ferr.seek(0)
        out = fout.read().decode("utf-8", errors="replace")
        err = ferr.read().decode("utf-8", errors="replace")
    code = os.waitstatus_to_exitcode(status)
    return subprocess.CompletedProcess([str(ACSCAL), *argv], code, out, err)


def _child(
    main: Callable[[list[str]], None], argv: list[str], cwd: Path | None, out: int, err: int
) -> None:  # pragma: no cover - runs in the forked child, which never returns
    code = 1
    try:
        import atexit

        atexit._clear()  # the test worker's handlers are not the command's
        os.setpgid(0, 0)  # its own group, as a shell's job (the detection workers join it)
        # a fresh interpreter's handlers (SIGPIPE stays ignored, as Python sets it)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(out, 1)
        os.dup2(err, 2)
        sys.stdin = io.TextIOWrapper(io.FileIO(0, "r", closefd=False))
        sys.stdout = io.TextIOWrapper(io.FileIO(1, "w", closefd=False), encoding="utf-8")
        sys.stderr = io.TextIOWrapper(
            io.FileIO(2, "w", closefd=False), encoding="utf-8", errors="backslashreplace"
        )
        sys.__stdout__, sys.__stderr__, sys.__stdin__ = sys.stdout, sys.stderr, sys.stdin
        os.environ.update(ENV)
        if cwd is not None:
            os.chdir(cwd)
        warnings.resetwarnings()
        for action, category, module in reversed(_DEFAULT_FILTERS):
            warnings.filterwarnings(action, category=category, module=module)
        sys.argv = [str(ACSCAL), *argv]
        try:
            main(argv)
            code = 0
        except SystemExit as exc:
            if exc.code is None:
                code = 0
            elif isinstance(exc.code, int):
                code = exc.code
            else:
                print(exc.code, file=sys.stderr)
                code = 1
        except BaseException:
            traceback.print_exc()
            code = 1
        atexit._run_exitfuncs()
    except BaseException:
        traceback.print_exc()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except BaseException:
                pass
        os._exit(code & 0xFF)


def _wait(pid: int, timeout: float | None, argv: list[str]) -> int:
    """The wait status of the child ``pid``; killed (its group) past ``timeout``."""
    deadline = None if timeout is None else time.monotonic() + timeout
    delay = 0.001
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            return status
        if deadline is not None and time.monotonic() > deadline:
            try:
                os.killpg(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(pid, 0)
            raise subprocess.TimeoutExpired([str(ACSCAL), *argv], timeout or 0.0)
        time.sleep(delay)
        delay = min(delay * 2, 0.02)
