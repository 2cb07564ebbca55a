"""joint_residuals.csv written then read (acs_cli.io.rig_residuals)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acs_cli.errors import InputError
from acs_cli.io.rig_residuals import (
    RESIDUAL_COLUMNS,
    JointResiduals,
    read_joint_residuals,
    write_joint_residuals,
)


def test_joints_and_recordings_round_trip(tmp_path: Path, rng: np.random.Generator) -> None:
    t = np.cumsum(rng.uniform(0.01, 0.1, 5)) + 1.7e9  # epoch seconds keep their digits
    used = np.array([True, True, False, True, True])
    hinge = {"pos": np.abs(rng.normal(size=5)), "rot": np.abs(rng.normal(size=5))}
    rigid = {"rot": np.abs(rng.normal(size=5)), "trans": np.abs(rng.normal(size=5))}
    series = [
        JointResiduals("knee", "walk", t, used, hinge),
        JointResiduals("knee", "squat", t[:3], used[:3], {k: v[:3] for k, v in hinge.items()}),
        JointResiduals("mount", "walk", t, np.ones(5, bool), rigid),
    ]
    path = tmp_path / "joint_residuals.csv"
    write_joint_residuals(path, series)
    assert path.read_text().splitlines()[0] == ",".join(RESIDUAL_COLUMNS)
    got = read_joint_residuals(path)
    assert [(g.joint, g.recording) for g in got] == [
        ("knee", "walk"), ("knee", "squat"), ("mount", "walk")
    ]  # fmt: skip
    assert np.array_equal(got[0].times, t) and np.array_equal(got[0].used, used)
    assert set(got[0].values) == {"pos", "rot"} and set(got[2].values) == {"rot", "trans"}
    for g, s in zip(got, series, strict=True):
        for k, v in s.values.items():
            np.testing.assert_array_equal(g.values[k], v)


def test_another_file_is_refused(tmp_path: Path) -> None:
    p = tmp_path / "x.csv"
    p.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match=r"not a joint_residuals\.csv"):
        read_joint_residuals(p)
    p.write_text(",".join(RESIDUAL_COLUMNS) + "\n0.0,default,j,yes,1,,\n")
    with pytest.raises(InputError, match="not 0 or 1"):
        read_joint_residuals(p)
    p.write_text(",".join(RESIDUAL_COLUMNS) + "\n0.0,default,j,1,abc,,\n")
    with pytest.raises(InputError, match="joint j"):
        read_joint_residuals(p)
    with pytest.raises(ValueError, match="no column"):
        write_joint_residuals(p, [JointResiduals("j", "r", np.zeros(1), np.ones(1, bool),
                                                 {"twist": np.zeros(1)})])  # fmt: skip
