"""``joint_type`` (issue 19, item 4): the artifacts' new optional keys and the run
configs' ``joint.joint_type`` / ``relpose.joint_type``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from test_run_config import _with, _write

from acs_cli.core.overlap import check_overlap_joint_type
from acs_cli.core.relpose import check_joint_type
from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header
from acs_cli.io.joint import JointSection
from acs_cli.io.relpose import RelativePose, RelposeArtifact, load_joint_artifact
from acs_cli.stages.run import load_run_config


def test_a_hinge_section_round_trips_and_a_ball_has_no_new_keys() -> None:
    ball = JointSection.from_estimate(np.ones(3), np.eye(3) * 1e-4, np.zeros(3), np.eye(3) * 1e-4)
    assert ball.with_axes("ball", {"a": np.eye(3)[0]}, {"a": 0.1}) is ball
    assert not {"type", "axis_in_a", "axis_in_a_std_deg"} & set(ball.to_plain())
    hinge = ball.with_axes("hinge", {"a": np.eye(3)[0], "b": np.eye(3)[2]}, {"a": 0.1, "b": 0.2})
    doc = hinge.to_plain()
    assert doc["type"] == "hinge" and doc["axis_in_b_std_deg"] == 0.2
    back = JointSection.parse(yaml.safe_load(yaml.safe_dump(_plain(doc))), None)
    assert back.type == "hinge"
    np.testing.assert_allclose(np.asarray(back.axis_in_b), [0, 0, 1])
    assert back.axis_in_a_std_deg == 0.1
    scaled = back.scaled(1000.0, "mm")  # a change of unit keeps the axes
    assert scaled.axis_in_a is not None and scaled.axis_in_a_std_deg == 0.1
    with pytest.raises(InputError, match="axis_in_a_std_deg"):
        JointSection.parse(_plain(doc) | {"axis_in_a_std_deg": -1.0}, None)


def _plain(doc: dict[str, Any]) -> dict[str, Any]:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in doc.items()}


def test_a_rigid_relpose_has_no_joint_and_says_so(tmp_path: Path) -> None:
    T = np.eye(4)
    rel = RelativePose(
        T_b_a=T, T_b_a_covariance=np.eye(6) * 1e-6, rpy_deg=np.zeros(3),
        rpy_deg_std=np.zeros(3), translation_b_in_a=np.zeros(3),
        translation_b_in_a_std=np.zeros(3), reference=0, reference_timestamp_a=0.0,
        reference_timestamp_b=0.0, T_wb_wa=T,
    )  # fmt: skip
    path = tmp_path / "relpose.yaml"
    header = make_header("relpose", {}, "test", {"length": "m"}, {})
    RelposeArtifact(rel, joint_type="rigid", header=header, source=str(path)).save(path)
    art = RelposeArtifact.load(path)
    assert art.joint_type == "rigid" and art.joint is None
    with pytest.raises(InputError, match="rigid pair"):
        art.require_joint()
    with pytest.raises(InputError, match="rigid pair"):
        load_joint_artifact(path)
    plain = tmp_path / "ball.yaml"
    RelposeArtifact(rel, header=header, source=str(plain)).save(plain)
    assert "joint_type" not in plain.read_text()


def test_the_checks_of_the_joint_types() -> None:
    check_joint_type("hinge")
    check_joint_type("rigid")
    with pytest.raises(InputError, match="ball joint only"):
        check_joint_type("rigid", "paper")
    with pytest.raises(InputError, match="unknown joint type"):
        check_joint_type("universal")
    check_overlap_joint_type("hinge")
    with pytest.raises(InputError, match="no joint point"):
        check_overlap_joint_type("rigid")


def test_run_configs_take_the_joint_types(tmp_path: Path) -> None:
    hinges = {"joint.scenario": "overlap", "joint.joint_type": "hinge"}
    cfg = load_run_config(_write(tmp_path, _with(hinges | {"relpose.joint_type": "hinge"})))
    assert cfg.joint is not None and cfg.joint.joint_type == "hinge"
    assert cfg.relpose is not None and cfg.relpose.joint_type == "hinge"
    # a rigid pair: no joint section, no self-calibration needed
    cfg = load_run_config(_write(tmp_path, _with({"joint": ..., "relpose.joint_type": "rigid"})))
    assert cfg.relpose is not None and cfg.relpose.joint_type == "rigid" and cfg.joint is None
    # the defaults are the ball's
    cfg = load_run_config(_write(tmp_path, _with({})))
    assert cfg.joint is not None and cfg.joint.joint_type == "ball"


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"joint.joint_type": "hinge"}, "joint.joint_type"),  # a fixed joint
        ({"joint.scenario": "overlap", "joint.joint_type": "rigid"}, "joint.joint_type"),
        ({"joint.scenario": "overlap", "joint.joint_type": "hinge", "joint.method": "paper"},
         "joint.joint_type"),
        ({"relpose.joint_type": "rigid"}, "relpose.joint_type"),  # with a joint section
        ({"relpose.joint_type": "hinge", "relpose.method": "paper"}, "relpose.joint_type"),
        ({"relpose.joint_type": "cardan"}, "relpose.joint_type"),
    ],
)  # fmt: skip
def test_bad_joint_types_are_named(tmp_path: Path, change: dict[str, Any], key: str) -> None:
    with pytest.raises(InputError) as exc:
        load_run_config(_write(tmp_path, _with(change)))
    assert key in str(exc.value)
