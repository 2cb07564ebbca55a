"""A silent failure of the self-calibration on real SfM output (issue 10), now a regression
test: the lifted linear start fell in a wrong minimum's basin (phi 0.683, the rotation noise
fitted at zero); the solver now also starts from a joint at either camera's centre and keeps
the most likely fit."""

from __future__ import annotations

from pathlib import Path

import pytest

from acs_cli.core.relpose import estimate_relpose
from acs_cli.errors import DegenerateMotionError
from acs_cli.io.trajectory import read_trajectory
from acs_cli.stages.common import pair_loaded

DATA = Path(__file__).resolve().parents[1] / "data" / "markerless_wrong_minimum"
#: mu_b / mu_a of the rendered truth (SfM units: each camera's mean step between frames)
PHI_TRUE = 0.9352


def test_self_calibration_finds_the_scale_or_refuses() -> None:
    pair = pair_loaded(read_trajectory(DATA / "poses_a.npz"), read_trajectory(DATA / "poses_b.npz"))
    try:
        est = estimate_relpose(pair.a.T_world_cam, pair.b.T_world_cam, unknown_scale=True)
    except DegenerateMotionError:
        return  # a refusal is an acceptable answer: not a silent wrong one
    assert est.phi_ba == pytest.approx(PHI_TRUE, rel=0.03)
