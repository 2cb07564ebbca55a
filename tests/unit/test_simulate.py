"""The simulation study stage: a tiny study end to end."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from acs_cli.errors import InputError
from acs_cli.stages import simulate
from acs_cli.stages.simulate import (
    MEASURES,
    METHODS,
    SCENARIOS,
    TRIAL_COLUMNS,
    SimulationConfig,
    run_simulate,
    run_study,
    summarise,
)

TINY = SimulationConfig(trials=3, levels=2, frames=30, seed=1)

#: Measures each scenario defines.
DEFINED = {
    "overlap": ("joint_err", "joint_rms_err", "crlb_joint_rms"),
    "fixed_joint": ("joint_err", "joint_rms_err", "crlb_joint_rms"),
    "relpose": ("joint_err", "joint_rms_err", "rot_err_deg", "rot_angle_err_deg", "trans_err"),
    "unknown_scale": (
        "joint_err",
        "joint_rms_err",
        "rot_err_deg",
        "rot_angle_err_deg",
        "trans_err",
        "scale_err",
    ),
}


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, Any], list[dict], Path]:
    out = tmp_path_factory.mktemp("study")
    calls: list[tuple[int, int]] = []
    result = run_simulate(out, TINY, progress=lambda done, total: calls.append((done, total)))
    assert calls[-1] == (6, 6) and len(calls) == 6
    with open(out / "trials.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    return result, rows, out


def test_rows_cover_the_design(study: tuple[dict[str, Any], list[dict], Path]) -> None:
    _, rows, _ = study
    assert len(rows) == len(SCENARIOS) * len(METHODS) * TINY.levels * TINY.trials
    assert list(rows[0]) == list(TRIAL_COLUMNS)
    levels = {(float(r["rot_noise_deg"]), float(r["trans_noise"])) for r in rows}
    assert levels == {(0.0, 0.0), (2.4, 0.1)}


def test_noise_free_trials_are_exact(study: tuple[dict[str, Any], list[dict], Path]) -> None:
    _, rows, _ = study
    exact = [r for r in rows if r["level"] == "0"]
    assert len(exact) == len(SCENARIOS) * len(METHODS) * TINY.trials
    for r in exact:
        assert r["error"] == "", r
        for m in DEFINED[r["scenario"]]:
            if m == "crlb_joint_rms":
                assert float(r[m]) == 0.0
            else:
                assert float(r[m]) < 1e-9, (r["scenario"], r["method"], m, r[m])
        for m in set(MEASURES) - set(DEFINED[r["scenario"]]):
            assert math.isnan(float(r[m]))


def test_noisy_trials_have_plausible_errors(
    study: tuple[dict[str, Any], list[dict], Path],
) -> None:
    _, rows, _ = study
    for r in rows:
        if r["level"] != "1" or r["error"]:
            continue
        assert 1e-4 < float(r["joint_err"]) < 1.0
        if r["scenario"] in ("overlap", "fixed_joint"):
            assert float(r["crlb_joint_rms"]) > 0
        if r["scenario"] == "unknown_scale":
            assert float(r["scale_err"]) < 0.2
            assert float(r["phi_true"]) > 0


def test_files_and_figures(study: tuple[dict[str, Any], list[dict], Path]) -> None:
    result, _, out = study
    for key in ("trials_csv", "summary_csv", "study_yaml"):
        assert Path(result[key]).is_file() and Path(result[key]).parent == out
    assert len(result["figures"]) == 8
    for stem, *_ in simulate.FIGURES:
        png = out / f"{stem}.png"
        assert str(png) in result["figures"]
        data = png.read_bytes()
        assert len(data) > 1000 and data[:8] == b"\x89PNG\r\n\x1a\n"
    assert not list(out.glob(".*tmp*"))  # atomic writes left no temporary file
    head = result["headline"]
    assert set(head["fixed_joint_rms_over_crlb"]) == set(METHODS)
    assert all(len(v) == TINY.levels for v in head["scale_accuracy"].values())
    assert result["n_rows"] == len(SCENARIOS) * len(METHODS) * TINY.levels * TINY.trials


def test_summary(study: tuple[dict[str, Any], list[dict], Path]) -> None:
    _, _, out = study
    with open(out / "summary.csv", newline="") as fh:
        summary = list(csv.DictReader(fh))
    assert len(summary) == len(SCENARIOS) * len(METHODS) * TINY.levels
    for s in summary:
        assert s["n_trials"] == str(TINY.trials)
        ratio = float(s["rms_over_crlb"])
        if s["scenario"] in ("overlap", "fixed_joint") and s["level"] == "1":
            assert ratio >= 0.5  # an estimator does not beat the bound by much on 3 trials
        else:
            assert math.isnan(ratio)
        if s["scenario"] == "unknown_scale":
            assert float(s["scale_accuracy"]) > 0.8


def test_reproducible_and_scenario_independent() -> None:
    cfg = SimulationConfig(trials=1, levels=2, seed=4, scenarios=("fixed_joint",))
    a = run_study(cfg)
    b = run_study(
        SimulationConfig(trials=1, levels=2, seed=4, scenarios=("overlap", "fixed_joint"))
    )
    b_fixed = [r for r in b if r["scenario"] == "fixed_joint"]
    assert len(a) == len(b_fixed) == 4
    for x, y in zip(a, b_fixed, strict=True):
        assert x["joint_err"] == y["joint_err"]


def test_summarise_counts_failures() -> None:
    base = {c: math.nan for c in TRIAL_COLUMNS}
    rows = []
    for trial, err in enumerate((0.1, 0.3, math.nan)):
        row = dict(base, scenario="fixed_joint", method="paper", level=1, trial=trial)
        row.update(rot_noise_deg=1.0, trans_noise=0.1, joint_err=err, error="")
        row.update(joint_rms_err=err, crlb_joint_rms=0.1)
        if math.isnan(err):
            row["error"] = "degenerate"
        rows.append(row)
    (s,) = summarise(rows)
    assert (s["n_trials"], s["n_failed"]) == (3, 1)
    assert s["joint_err_mean"] == pytest.approx(0.2)
    assert s["joint_err_std"] == pytest.approx(0.1)
    assert s["rms_over_crlb"] == pytest.approx(np.sqrt((0.01 + 0.09) / 2) / 0.1)
    assert math.isnan(s["scale_err_mean"])


def test_degenerate_trial_is_a_failure_row(monkeypatch: pytest.MonkeyPatch) -> None:
    from acs_cli.errors import DegenerateMotionError

    def boom(*args: object, **kwargs: object) -> None:
        raise DegenerateMotionError("hinge motion")

    monkeypatch.setattr(simulate, "estimate_joint_overlap", boom)
    rows = run_study(SimulationConfig(trials=1, levels=2, scenarios=("overlap",)))
    assert len(rows) == 4
    assert all(r["error"] == "hinge motion" and math.isnan(r["joint_err"]) for r in rows)
    assert all(s["n_failed"] == 1 for s in summarise(rows))


def test_bad_config() -> None:
    with pytest.raises(InputError):
        SimulationConfig(levels=1)
    with pytest.raises(InputError):
        SimulationConfig(scenarios=("hinge",))
    assert SimulationConfig(levels=3).noise_levels() == [(0.0, 0.0), (1.2, 0.05), (2.4, 0.1)]
