"""Typer command line (thin: parses options, calls the stages, prints)."""

import os

# Per-frame work is many small BLAS calls; a thread pool costs more than it gains (about 2x
# slower end to end on 2 cores). This runs before acs_cli.cli.main imports numpy; a user's
# own setting wins.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
