"""Running the installed ``acscal`` console script as a user would (shared by the e2e tests)."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

ACSCAL = Path(sys.executable).with_name("acscal")


def acscal(
    *args: str | Path,
    cwd: Path | None = None,
    timeout: float | None = 300,
    preexec_fn: Callable[[], None] | None = None,
) -> subprocess.CompletedProcess[str]:
    """Run ``acscal ARGS`` (wide, uncoloured output) and return the finished process
    (``preexec_fn`` runs in the child before ``acscal`` starts, e.g. to set a limit)."""
    env = dict(os.environ, COLUMNS="200", NO_COLOR="1")
    return subprocess.run(
        [str(ACSCAL), *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=timeout,
        preexec_fn=preexec_fn,
    )
