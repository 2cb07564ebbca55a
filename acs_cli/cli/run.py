"""``acscal run CONFIG``: the whole calibration from a config file (see ``configs/``).

Thin Typer command over :mod:`acs_cli.stages.run`; :func:`register` adds it to the app.
"""

from __future__ import annotations

from dataclasses import replace
from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from acs_cli.cli.help_format import AcsCommand
from acs_cli.cli.output import AcceptWeakOpt, JsonOpt, emit, out, warn

__all__ = ["register", "run"]

#: Statuses of a stage that wrote its outputs in this run (not skipped, reused or left out).
WROTE = frozenset({"ran", "written"})


class Stage(str, Enum):
    intrinsics = "intrinsics"
    poses = "poses"
    joint = "joint"
    relpose = "relpose"
    rig = "rig"


def run(
    config: Annotated[Path, typer.Argument(help="Run config (YAML, schema acscal/run-config).")],
    force: Annotated[
        bool, typer.Option("--force", help="Rerun every stage, even those up to date.")
    ] = False,
    only: Annotated[
        Stage | None,
        typer.Option(
            "--only", help="Run only this stage (the others' outputs must exist already)."
        ),
    ] = None,
    accept_weak: AcceptWeakOpt = False,
    json_out: JsonOpt = False,
) -> None:
    """Run intrinsics, poses, joint and relpose as a config file says.

    A stage whose inputs (content hashes), options and acscal version are unchanged since
    its last successful run is skipped; --force reruns everything. Relative paths in the
    config resolve against the config file's folder. See configs/*.yaml for the schema.

    Example:

        acscal run configs/fixed_joint.yaml
    """
    from rich.table import Table

    from acs_cli.io.artifacts import to_plain
    from acs_cli.stages.run import StageResult, load_run_config, run_pipeline

    cfg = load_run_config(config)
    if accept_weak:
        cfg = replace(cfg, accept_weak=True)

    def progress(res: StageResult) -> None:
        extra = f" ({res.seconds:.1f} s)" if res.status == "ran" else ""
        out.print(f"{res.stage}: {res.status}{extra}")
        warn(f"{res.stage}: {w}" for w in res.warnings)

    result = run_pipeline(
        cfg, force=force, only=None if only is None else only.value, on_stage=progress
    )
    table = Table(title=f"acscal run {config}", title_justify="left")
    table.add_column("stage")
    table.add_column("status")
    table.add_column("output")
    table.add_column("key numbers")
    for res in result.stages:
        shown = ", ".join(_short(p, cfg.output) for p in res.outputs[:1])
        table.add_row(res.stage, res.status, shown, res.numbers)
    out.print(table)
    n_run, n_skip = len(result.ran), len(result.skipped)
    if n_run == 0 and n_skip:
        out.print(f"all {n_skip} stages skipped: inputs unchanged since the last run")
    else:
        out.print(f"{n_run} stage(s) ran, {n_skip} skipped (unchanged) in {result.seconds:.1f} s")
    out.print(f"outputs in {cfg.output}")
    emit(
        {
            "config": config,
            "output": cfg.output,
            "seconds": result.seconds,
            "ran": result.ran,
            "skipped": result.skipped,
            "stages": [to_plain(res) for res in result.stages],
        },
        written=[p for res in result.stages if res.status in WROTE for p in res.outputs],
        warnings=[f"{res.stage}: {w}" for res in result.stages for w in res.warnings],
    )


def _short(path: Path, base: Path) -> str:
    try:
        return path.relative_to(base).as_posix()
    except ValueError:
        return str(path)


def register(app: typer.Typer) -> None:
    """Add ``run`` to the ``acscal`` app."""
    app.command(cls=AcsCommand)(run)
