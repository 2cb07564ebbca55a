"""The one policy for weak results (acs_cli.core.quality) and its artifact section."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from acs_cli.core.quality import (
    ACCEPT_WEAK_FLAG,
    JOINT_STD,
    REJECTED,
    RESIDUAL,
    RULES,
    Measure,
    joint_measures,
    judge,
    length_scale,
)
from acs_cli.errors import DegenerateMotionError
from acs_cli.io.joint import JointArtifact, JointSection
from acs_cli.io.verdict import VerdictSection, weak_marks


def test_levels_and_not_determined() -> None:
    assert Measure(JOINT_STD, 0.01).level == "good"
    assert Measure(JOINT_STD, 0.07).level == "weak"
    assert Measure(JOINT_STD, 0.2).level == "refused"
    assert Measure(JOINT_STD, float("nan")).level == "refused"
    assert Measure(JOINT_STD, float("inf")).level == "refused"
    assert all(r.warn < r.refuse for r in RULES.values())


def test_judge_refuses_naming_each_measure_and_the_flag() -> None:
    ms = [Measure(JOINT_STD, 0.2, "the joint in A"), Measure(RESIDUAL, 0.01, "the joint in A")]
    with pytest.raises(DegenerateMotionError) as err:
        judge(ms)
    assert "standard deviation" in err.value.message and ACCEPT_WEAK_FLAG in err.value.message
    assert "residual RMS" not in err.value.message  # only the refused measure
    assert err.value.details["verdict"]["level"] == "refused"
    v = judge(ms, accept_weak=True)
    assert v.level == "refused" and v.weak
    assert any(ACCEPT_WEAK_FLAG in w for w in v.warnings())


def test_a_large_residual_with_a_determined_estimate_is_a_warning() -> None:
    """Noisy poses about a well-determined joint: weak, written, no format advice; with a
    diagnosis that finds a better reading, or a std past its level too, refused."""
    ms = [Measure(JOINT_STD, 0.01, "the joint in A"), Measure(RESIDUAL, 0.31, "the joint in A")]
    v = judge(ms)
    assert v.level == "weak" and v.weak
    (note,) = v.warnings()
    assert "31%" in note and "refusal level 25%" in note and "weak result" in note
    assert "check the trajectories" not in note and "stds include it" in note
    finding = "camera A's quaternions look written in w-x-y-z order"
    with pytest.raises(DegenerateMotionError) as err:
        judge(ms, findings=[finding])
    assert err.value.message.startswith(finding) and "residual RMS" in err.value.message
    with pytest.raises(DegenerateMotionError) as err:
        judge([Measure(JOINT_STD, 0.2, "the joint in A"), ms[1]])
    assert "residual RMS" in err.value.message and "standard deviation" in err.value.message


def test_a_good_verdict_has_no_warnings() -> None:
    v = judge([Measure(JOINT_STD, 0.01), Measure(REJECTED, 0.0)])
    assert v.level == "good" and v.warnings() == [] and not v.weak
    assert judge([]).level == "good"


def test_length_scale_is_the_joint_distance_or_a_tenth_of_the_travel() -> None:
    T = np.tile(np.eye(4), (4, 1, 1))
    T[:, 0, 3] = [-1.0, 1.0, -1.0, 1.0]  # RMS travel 1
    assert length_scale(np.array([0.0, 0.0, 0.5]), T) == pytest.approx(0.5)
    assert length_scale(np.array([0.0, 0.0, 0.01]), T) == pytest.approx(0.1)


def test_joint_measures(rng: np.random.Generator) -> None:
    T = np.tile(np.eye(4), (10, 1, 1))
    o = np.array([0.0, 0.0, 0.5])
    cov = np.diag([1e-4, 4e-4, 1e-6])  # largest std 0.02 = 4% of 0.5
    mask = np.ones(10, bool)
    mask[:2] = False
    ms = {m.rule.key: m for m in joint_measures(o, cov, T, 0.02, mask, "A")}
    assert ms["joint_std_fraction"].value == pytest.approx(0.04)
    assert ms["residual_fraction"].value == pytest.approx(0.04)
    assert ms["rejected_fraction"].value == pytest.approx(0.2)
    assert judge(ms.values()).level == "weak"


def test_the_verdict_round_trips_through_an_artifact(tmp_path: Path) -> None:
    v = judge([Measure(JOINT_STD, 0.2, "the joint in A"), Measure(RESIDUAL, 0.01)], True)
    art = JointArtifact(
        scenario="fixed_joint",
        joint=JointSection(position_in_a=np.array([0.0, 0.0, 0.5])),
        verdict=VerdictSection.from_verdict(v),
        header={"schema": "acscal/joint", "schema_version": 1},
        warnings=v.warnings(),
    )
    art.save(tmp_path / "j.yaml")
    back = JointArtifact.load(tmp_path / "j.yaml")
    assert back.verdict is not None
    assert back.verdict == VerdictSection.from_verdict(v)
    assert back.verdict.level == "refused" and back.verdict.accepted_weak
    assert "with --accept-weak" in weak_marks("j.yaml", back.verdict)[0]
    assert weak_marks("j.yaml", VerdictSection()) == []
