"""The joint-model registry (issue 19, item 5): every joint type is one module, and the
engine asks the registry, not the type's name. A joint type registered here, in the test
only, is accepted by the rig's topology, solve, artifact and URDF export."""

from __future__ import annotations

import numpy as np
import pytest

from acs_cli.core.joints import JOINT_MODELS, joint_model, joint_types
from acs_cli.core.joints.ball import Ball
from acs_cli.core.joints.base import Edge, UrdfJoint
from acs_cli.core.rig import rig_topology
from acs_cli.core.rig_solve import CameraTrack, estimate_rig
from acs_cli.errors import InputError
from acs_cli.io.rig_export import urdf_from_rig
from acs_cli.stages.rig import rig_artifact
from sample_data_gen.rig_sim import rig_recording

JOINTS = (("j01", ("cam0", "cam1"), "ball"), ("r12", ("cam1", "cam2"), "rigid"))


class Knuckle(Ball):
    """A toy joint type: a spherical joint that exports as one URDF ``spherical`` joint
    (a type name acscal does not have)."""

    name = "knuckle"

    def urdf(
        self,
        joint: Edge,
        parent: str,
        child: str,
        T_parent_child: np.ndarray,
        axis: np.ndarray | None,
    ) -> tuple[list[str], list[UrdfJoint], str]:
        return [], [UrdfJoint(joint.name, "spherical", parent, child, T_parent_child)], "knuckle"


def _solve(joints: tuple, rng: np.random.Generator):
    rec = rig_recording(rng, 40, joints=JOINTS, sigma_rot_deg=0.2, sigma_trans=0.002)
    topo = rig_topology(rec.topology.cameras, joints, "cam0")
    n = rec.timestamps.size
    tracks = {c: CameraTrack(T, np.ones(n, bool)) for c, T in rec.T_wc_c.items()}
    return estimate_rig(topo, tracks, reference_frame=2)


def test_the_registry_has_the_three_types() -> None:
    assert joint_types() == ("ball", "hinge", "rigid")
    for name, model in JOINT_MODELS.items():
        assert model.name == name
        assert len(model.residual_kinds) >= 1
    with pytest.raises(KeyError, match="ball, hinge, rigid"):
        joint_model("universal")


def test_an_unregistered_type_is_refused_naming_the_registered_ones() -> None:
    with pytest.raises(InputError, match="choose one of ball, hinge, rigid"):
        rig_topology(("a", "b"), (("j", ("a", "b"), "knuckle"),), "a")


def test_a_type_registered_in_one_module_is_accepted_by_the_engine(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(JOINT_MODELS, "knuckle", Knuckle())
    knuckle = (("j01", ("cam0", "cam1"), "knuckle"), JOINTS[1])
    ball = _solve(JOINTS, np.random.default_rng(3))
    est = _solve(knuckle, np.random.default_rng(3))
    # the same maths as the ball it copies: the same numbers
    assert est.edges["j01"].joint.type == "knuckle"
    for c in ("cam0", "cam1"):
        np.testing.assert_array_equal(
            est.edges["j01"].position_in[c], ball.edges["j01"].position_in[c]
        )
    for c in ("cam1", "cam2"):
        np.testing.assert_array_equal(est.cameras[c].T_cam_ref, ball.cameras[c].T_cam_ref)
    # its outputs: the artifact's sections and its own URDF joint
    rig = rig_artifact(est, "m", [])
    assert rig.joints["j01"].model.has_point
    assert "position_in" in rig.body()["joints"]["j01"]
    urdf = urdf_from_rig(rig)
    assert '<joint name="j01" type="spherical">' in urdf
    assert "j01_x_link" not in urdf
