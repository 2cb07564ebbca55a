"""A joint file's covariances and length unit, checked where it is read (issue 13, item 6).

A ``joint.yaml`` (or a ``relpose.yaml`` given as ``--joint``) is refused, naming the file and
the key, when a covariance is not a covariance on its own axes' scales or disagrees with its
stds; a joint in another unit than the trajectories' is converted (known units) or refused;
an unknown-scale ``relpose.yaml``'s joint is reused only on the trajectories it came from.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from acs_cli.errors import InputError
from acs_cli.io.artifacts import make_header
from acs_cli.io.joint import JointArtifact, JointSection
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.relpose import RelativePose, RelposeArtifact, Scale, load_joint_section
from acs_cli.io.validate import as_covariance3
from acs_cli.stages.joint import read_joint_in_units

COV_A = np.array([[3.7e-6, 1e-7, 0.0], [1e-7, 3.4e-6, 0.0], [0.0, 0.0, 5.2e-6]])
POS_A = np.array([-0.65, -0.18, 1.67])
POS_B = np.array([0.44, -1.09, 0.0])


def _joint_file(path: Path, unit: str = "m", factor: float = 1.0) -> Path:
    """A fixed-joint ``joint.yaml`` whose lengths are in ``unit`` (``factor`` per metre)."""
    section = JointSection.from_estimate(POS_A, COV_A, POS_B, 0.5 * COV_A, units="m").scaled(
        factor, unit
    )
    header = make_header(
        "joint", {}, method="test", units={"length": unit, "angles": "deg"}, frames={}
    )
    JointArtifact(scenario="fixed_joint", joint=section, header=header).save(path)
    return path


def _edit(path: Path, edit: dict[str, Any]) -> Path:
    doc = yaml.safe_load(path.read_text())
    doc["joint"].update(edit)
    path.write_text(yaml.safe_dump(doc))
    return path


def test_covariance_judged_on_each_axis_scale() -> None:
    # indefinite in its two small axes (correlation 1.5): the old test, relative to the
    # largest entry, passed it and relpose's Cholesky raised LinAlgError
    mixed = [[1.0, 0.0, 0.0], [0.0, 1e-8, 1.5e-8], [0.0, 1.5e-8, 1e-8]]
    with pytest.raises(InputError, match="'k' must be a positive semi-definite"):
        as_covariance3(mixed, "k", "f.yaml")
    skew = [[1.0, 0.0, 0.0], [0.0, 1e-8, 5e-9], [0.0, -5e-9, 1e-8]]
    with pytest.raises(InputError, match="'k' must be a symmetric"):
        as_covariance3(skew, "k", "f.yaml")
    with pytest.raises(InputError, match="positive semi-definite"):
        as_covariance3([[0.0, 1e-9, 0.0], [1e-9, 0.0, 0.0], [0.0, 0.0, 0.0]], "k", None)
    # a valid covariance of very different axes, and a singular one, pass unchanged
    ok = np.diag([1.0, 1e-8, 1e-12])
    ok[1, 2] = ok[2, 1] = 0.99e-10
    np.testing.assert_array_equal(as_covariance3(ok, "k", None), ok)
    singular = np.diag([1.0, 0.0, 1.0])
    np.testing.assert_array_equal(as_covariance3(singular, "k", None), singular)


def test_joint_yaml_bad_covariance_names_file_and_key(tmp_path: Path) -> None:
    p = _joint_file(tmp_path / "joint.yaml")
    cases = {
        "symmetric": {"covariance_b": [[2e-6, 1e-6, 0], [-1e-6, 2e-6, 0], [0, 0, 2e-6]]},
        "positive semi-definite": {
            "covariance_a": [[1e-2, 0, 0], [0, 1e-8, 1.5e-8], [0, 1.5e-8, 1e-8]],
            "position_in_a_std": None,
        },
        "disagrees with the square roots": {"position_in_a_std": [0.2, 0.2, 0.2]},
        "must not be negative": {"covariance_a": None, "position_in_a_std": [-1e-3, 1e-3, 1e-3]},
    }
    for phrase, edit in cases.items():
        bad = _edit(_joint_file(tmp_path / f"{len(phrase)}.yaml"), edit)
        with pytest.raises(InputError, match=phrase) as exc:
            read_joint_in_units(bad, "m")
        assert exc.value.path == str(bad)
        assert "joint." in exc.value.message
    # the stds alone (no covariance) are still accepted, and give the covariance
    p = _edit(p, {"covariance_a": None})
    np.testing.assert_allclose(
        load_joint_section(p).covariance("a"), np.diag(np.diag(COV_A)), rtol=1e-12
    )


def test_joint_units_disagree_with_header(tmp_path: Path) -> None:
    p = _edit(_joint_file(tmp_path / "joint.yaml"), {"units": "mm"})
    with pytest.raises(InputError, match=r"'joint.units' \(mm\).*'units.length' \(m\)") as exc:
        read_joint_in_units(p, "m")
    assert exc.value.path == str(p)


def test_joint_in_mm_converted_to_the_trajectories_unit(tmp_path: Path) -> None:
    p = _joint_file(tmp_path / "joint_mm.yaml", "mm", 1000.0)
    joint, notes = read_joint_in_units(p, "m")
    np.testing.assert_allclose(joint.position_in_a, POS_A, rtol=1e-12)
    np.testing.assert_allclose(joint.position_in_b, POS_B, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(joint.covariance("a"), COV_A, rtol=1e-12, atol=1e-20)
    np.testing.assert_allclose(joint.covariance("b"), 0.5 * COV_A, rtol=1e-12, atol=1e-20)
    assert joint.units == "m"
    assert len(notes) == 1 and "in mm" in notes[0] and "converted to m" in notes[0]
    # metres to cm trajectories; --joint-metric always wants metres
    joint, notes = read_joint_in_units(_joint_file(tmp_path / "m.yaml"), "cm")
    np.testing.assert_allclose(joint.position_in_a, 100 * POS_A, rtol=1e-12)
    joint, notes = read_joint_in_units(p, "cm", unknown_scale=True, metric=True)
    np.testing.assert_allclose(joint.position_in_a, POS_A, rtol=1e-12)
    assert joint.units == "m" and notes
    # same unit: no conversion, no note
    joint, notes = read_joint_in_units(p, "mm")
    np.testing.assert_allclose(joint.position_in_a, 1000 * POS_A, rtol=1e-12)
    assert notes == []


def test_joint_in_an_unknown_unit_refused(tmp_path: Path) -> None:
    p = _joint_file(tmp_path / "joint.yaml", "furlong", 1 / 201.168)
    with pytest.raises(InputError, match="'furlong' but the trajectories are in 'm'") as exc:
        read_joint_in_units(p, "m")
    assert exc.value.path == str(p)
    with pytest.raises(InputError, match="'m' but the trajectories are in 'px'"):
        read_joint_in_units(_joint_file(tmp_path / "m.yaml"), "px")
    joint, notes = read_joint_in_units(p, "furlong")  # the same unknown unit: as it is
    assert notes == [] and joint.units == "furlong"


def _relpose_file(path: Path, poses: tuple[Path, Path], unknown_scale: bool) -> Path:
    inputs = {"poses_a": poses[0], "poses_b": poses[1]}
    header = make_header("relpose", inputs, method="test", units={"length": "m"}, frames={})
    if unknown_scale:
        header["units"]["length"] = "B units (camera B's trajectory units)"
    RelposeArtifact(
        relative_pose=RelativePose(T_b_a=np.eye(4)),
        joint=JointSection.from_estimate(POS_A, COV_A, POS_B, COV_A),
        scale=Scale(phi_ba=2.5) if unknown_scale else None,
        header=header,
    ).save(path)
    return path


def test_unknown_scale_relpose_reused_only_on_its_own_trajectories(tmp_path: Path) -> None:
    own = (tmp_path / "a.tum", tmp_path / "b.tum")
    other = (tmp_path / "c.tum", tmp_path / "d.tum")
    for i, p in enumerate((*own, *other)):
        p.write_text(f"{i} 0 0 0 0 0 0 1\n")
    rel = _relpose_file(tmp_path / "relpose.yaml", own, unknown_scale=True)
    own, other = (tuple(PosesArtifact.load(p) for p in ps) for ps in (own, other))
    for unknown_scale in (True, False):  # A's and B's units are those of these very files
        joint, notes = read_joint_in_units(rel, "m", unknown_scale=unknown_scale, poses=own)
        np.testing.assert_array_equal(joint.position_in_a, POS_A)
        assert notes == []
    refusals = [
        ({"poses": other}, "these are other trajectories"),
        ({"poses": own, "unknown_scale": True, "metric": True}, "not metres"),
        ({"poses": None}, "these are other trajectories"),
    ]
    for kwargs, phrase in refusals:
        with pytest.raises(InputError, match=phrase) as exc:
            read_joint_in_units(rel, "m", **kwargs)
        assert exc.value.path == str(rel)
        assert "metric joint.yaml from a fixed-joint session" in exc.value.message
    # a known-scale relpose's joint is in its length unit, like a joint.yaml's
    known = _relpose_file(tmp_path / "known.yaml", own, unknown_scale=False)
    joint, notes = read_joint_in_units(known, "mm", poses=other)
    np.testing.assert_allclose(joint.position_in_a, 1000 * POS_A, rtol=1e-12)
    assert notes
