"""The rig's tree: validation (every error names the key), paths and chaining."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core import se3
from acs_cli.core.rig import RigTopology, rig_topology
from acs_cli.errors import InputError
from sample_data_gen.acs_sim import random_transform

CAMS = ["cam0", "cam1", "cam2", "cam3", "cam4"]
JOINTS = [
    ("r01", ["cam0", "cam1"], "rigid"),
    ("j02", ["cam0", "cam2"], "ball"),
    ("j23", ["cam2", "cam3"], "hinge"),
    ("r43", ["cam4", "cam3"], "rigid"),
]


def test_tree_order_visits_each_camera_once_after_its_parent() -> None:
    topo = rig_topology(CAMS, JOINTS, "cam0")
    steps = topo.tree_order()
    assert [s.target for s in steps] == ["cam1", "cam2", "cam3", "cam4"]
    seen = {"cam0"}
    for s in steps:
        assert s.source in seen
        seen.add(s.target)
    # r43 is written [cam4, cam3]: reaching cam4 from cam3 walks it backwards
    assert not steps[-1].forward and steps[0].forward


def test_paths_go_up_to_the_common_ancestor_and_down() -> None:
    topo = rig_topology(CAMS, JOINTS, "cam0")
    path = topo.path("cam1", "cam4")
    assert [(s.source, s.target) for s in path] == [
        ("cam1", "cam0"),
        ("cam0", "cam2"),
        ("cam2", "cam3"),
        ("cam3", "cam4"),
    ]
    assert topo.path("cam2", "cam2") == []


def _chain(topology: RigTopology, edge: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``T_cam_ref`` of every camera from one ``T_q_p`` per edge, along the tree's steps."""
    out = {topology.reference: np.eye(4)}
    for step in topology.tree_order():
        T = edge[step.joint.name]
        out[step.target] = (T if step.forward else se3.invert_transforms(T)) @ out[step.source]
    return out


def test_chained_transforms_agree_with_direct_composition(rng: np.random.Generator) -> None:
    topo = rig_topology(CAMS, JOINTS, "cam2")  # any camera can be the reference
    T_W = {c: random_transform(rng) for c in CAMS}  # T_world_cam at one instant
    edge = {
        name: se3.invert_transforms(T_W[b[1]]) @ T_W[b[0]]  # T_q_p
        for name, b, _ in JOINTS
    }
    T_ref = _chain(topo, edge)
    np.testing.assert_allclose(T_ref["cam2"], np.eye(4), atol=1e-12)
    for c in CAMS:
        want = se3.invert_transforms(T_W[c]) @ T_W["cam2"]
        np.testing.assert_allclose(T_ref[c], want, atol=1e-10)


@pytest.mark.parametrize(
    ("joints", "key", "words"),
    [
        ([*JOINTS, ("x14", ["cam1", "cam4"], "ball")], "joints.x14.between", "cycle"),
        ([*JOINTS[:3], ("r43", ["cam9", "cam3"], "rigid")], "joints.r43.between", "cam9"),
        ([*JOINTS, ("again", ["cam3", "cam2"], "ball")], "joints.again.between", "already"),
        (JOINTS[:3], "cameras.cam4", "in no joint"),
        ([*JOINTS[:3], ("r43", ["cam4", "cam3"], "slider")], "joints.r43.type", "slider"),
        ([*JOINTS[:3], ("r43", ["cam3", "cam3"], "rigid")], "joints.r43.between", "itself"),
        ([*JOINTS[:3], ("r43", ["cam4"], "rigid")], "joints.r43.between", "two cameras"),
    ],
)
def test_bad_trees_name_the_key(joints: list, key: str, words: str) -> None:
    with pytest.raises(InputError) as err:
        rig_topology(CAMS, joints, "cam0")
    assert key in err.value.message and words in err.value.message


def test_unknown_reference_is_named() -> None:
    with pytest.raises(InputError, match=r"reference\.camera"):
        rig_topology(CAMS, JOINTS, "cam7")
