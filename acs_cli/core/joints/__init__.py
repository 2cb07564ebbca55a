"""The joint-model registry: one :class:`~acs_cli.core.joints.base.JointModel` per joint
type (docs/joint-types.md says how to add one).

:data:`JOINT_MODELS` maps a type's name (``type: ball`` in a rig config) to its model; the
engine (the rig solve, the rig bundle, the rig artifact, the URDF export and the config's
checks) asks :func:`joint_model` rather than testing names.
"""

from __future__ import annotations

from acs_cli.core.joints.ball import Ball
from acs_cli.core.joints.base import JointModel
from acs_cli.core.joints.hinge import Hinge
from acs_cli.core.joints.rigid import Rigid

__all__ = ["JOINT_MODELS", "JointModel", "joint_model", "joint_types"]

#: Every joint type's model, by name, in the order messages list them.
JOINT_MODELS: dict[str, JointModel] = {m.name: m for m in (Ball(), Hinge(), Rigid())}


def joint_types() -> tuple[str, ...]:
    """The names of the registered joint types."""
    return tuple(JOINT_MODELS)


def joint_model(joint_type: str) -> JointModel:
    """The model of ``joint_type``.

    Raises
    ------
    KeyError
        Naming the registered types, for a name that is not one.
    """
    try:
        return JOINT_MODELS[joint_type]
    except KeyError:
        raise KeyError(
            f"{joint_type!r} is not a joint type; choose one of {', '.join(JOINT_MODELS)}"
        ) from None
