"""Run configs (``acscal run CONFIG``): the file's pydantic models and the checked configs.

Two versions share ``schema: acscal/run-config``:

- version 1 (:class:`RunConfig`): cameras ``a`` and ``b``, the joint and relpose stages;
- version 2, a rig (:class:`RigRunConfig`): named cameras (or ``recordings`` of them) and
  the joints between them; a config with ``joints`` is one.

:func:`load_run_config` reads a file and :func:`parse_run_config` checks a loaded document:
pydantic checks each key's type and range (strict: ``"3"`` is not a number, ``true`` is not
an integer; an unknown key is refused), then the rules that tie keys together are checked
(either ``poses`` or ``images``; a board with images; the joints form a tree; ...). Every
error is an :class:`~acs_cli.errors.InputError` of one line naming the file and the dotted
key, ``key 'cameras.cam1.scale': must be one of known, unknown; got 'metric'``. Paths are
resolved against the config file's folder (``~`` expanded); an optional key set to null is
the same as leaving it out.

The JSON Schema of both versions, for editors, is ``docs/run-config.schema.json``::

    python -m acs_cli.io.config --schema > docs/run-config.schema.json
"""

from __future__ import annotations

import json
import os
import re
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    Tag,
    TypeAdapter,
    ValidationError,
    ValidatorFunctionWrapHandler,
    WrapValidator,
)
from pydantic_core import ErrorDetails, PydanticCustomError

from acs_cli.core.checkerboard import MAX_BOARD_CORNERS
from acs_cli.core.intrinsics import MODELS
from acs_cli.core.joints import joint_model
from acs_cli.core.pairing import PAIR_BY
from acs_cli.core.rig import JOINT_TYPES, RigTopology, rig_topology
from acs_cli.errors import InputError
from acs_cli.io.artifacts import load_yaml_file
from acs_cli.io.validate import short_repr

if TYPE_CHECKING:
    from acs_cli.core.targets import MarkerTarget

__all__ = [
    "CONFIG_SCHEMA",
    "CONFIG_VERSION",
    "DEFAULT_RECORDING",
    "RIG_CONFIG_VERSION",
    "CameraSpec",
    "JointSpec",
    "RelposeSpec",
    "RigCameraSpec",
    "RigJointSpec",
    "RigRecordingSpec",
    "RigRunConfig",
    "RunConfig",
    "is_rig_config",
    "json_schema",
    "load_run_config",
    "parse_rig_config",
    "parse_run_config",
]

CONFIG_SCHEMA = "acscal/run-config"
CONFIG_VERSION = 1
RIG_CONFIG_VERSION = 2
CAMERAS = ("a", "b")
METHODS = ("refined", "paper")
JOINT_SCENARIOS = ("fixed_joint", "overlap")
INTRINSICS_FROM = ("all", "joint")
SCALES = ("known", "unknown")
FRONT_ENDS = ("board", "sfm")
SFM_MATCHING = ("auto", "sequential", "exhaustive")
TRAJECTORY_FORMATS = ("auto", "tum", "kitti", "colmap", "npz")
#: The recording of a config written without ``recordings`` (one recording).
DEFAULT_RECORDING = "default"
#: ``world``: every body's poses in one world, or each in its own.
WORLDS = ("separate", "shared")
#: Camera keys that only apply to a camera given as an image folder.
_IMAGE_KEYS = ("front_end", "intrinsics", "timestamps", "fps")
#: Keys of a camera entry that go with ``video`` (frame selection, see acs_cli.io.video).
_VIDEO_KEYS = ("every", "max_frames", "skip_blurred", "min_change")
#: Settings of a body that every recording of it must give alike.
_BODY_KEYS = ("unknown_scale", "model", "front_end", "intrinsics")
#: A run config's board fields when it names a target instead (unused then; the defaults
#: of :class:`acs_cli.stages.intrinsics.IntrinsicsConfig`)
_UNUSED_BOARD = (9, 6, 0.025)


# --------------------------------------------------------------------------- checked configs


@dataclass(frozen=True)
class CameraSpec:
    """One camera of a run: its joint-motion images (optional) and its lens model."""

    name: str
    images: Path | None
    model: str = "pinhole"
    #: where image times come from (``acscal poses --timestamps`` / ``--fps``), for every
    #: folder of this camera
    timestamps: Path | None = None
    fps: float | None = None
    #: with ``video``: its frames used (``--every``, ``--max-frames``); ``images`` then
    #: holds the video file
    every: int = 1
    max_frames: int | None = None
    #: with ``video`` or ``bag``: skip blurred frames, and views that barely change
    #: (``--skip-blurred``, ``--min-change``)
    skip_blurred: bool = False
    min_change: float | None = None
    #: with ``bag``: the image topic (``images`` then holds the bag)
    topic: str | None = None


@dataclass(frozen=True)
class JointSpec:
    """The joint stage's options (Algorithm I or II)."""

    scenario: str
    method: str = "refined"
    bundle: bool = True
    #: the overlap's joint: ``ball`` or ``hinge`` (``joint --overlap --joint-type``)
    joint_type: str = "ball"


@dataclass(frozen=True)
class RelposeSpec:
    """The relpose stage's options and its general-motion image folders."""

    images: dict[str, Path]
    method: str = "refined"
    unknown_scale: bool = False
    self_calibrate: bool = False
    reference: int = 0
    bundle: bool = True
    #: the two-body rig's joint (``relpose --joint-type``)
    joint_type: str = "ball"


@dataclass(frozen=True)
class RunConfig:
    """A checked run configuration; every path is resolved against the config's folder."""

    path: Path
    output: Path
    cols: int
    rows: int
    square: float
    cameras: dict[str, CameraSpec]
    intrinsics_from: dict[str, Path] | None = None
    #: an AprilGrid or ChArUco (config key ``target``) instead of the ``cols x rows`` board
    target: MarkerTarget | None = None
    intrinsics_images: str = "all"
    joint: JointSpec | None = None
    relpose: RelposeSpec | None = None
    workers: int | None = None
    #: write results past a refusal level, marked weak (``acscal run --accept-weak``)
    accept_weak: bool = False


@dataclass(frozen=True)
class RigCameraSpec:
    """One camera of a rig config: a trajectory file, or an image folder of a board."""

    name: str
    poses: Path | None = None
    format: str = "auto"
    images: Path | None = None
    model: str = "pinhole"
    unknown_scale: bool = False
    #: how an image folder becomes poses: ``board`` (checkerboard intrinsics and PnP) or
    #: ``sfm`` (structure from motion on natural images: up to scale)
    front_end: str = "board"
    #: for ``front_end: sfm``: an intrinsics file (else COLMAP self-calibrates)
    intrinsics: Path | None = None
    #: with ``images``: where image times come from (``acscal poses --timestamps``/``--fps``)
    timestamps: Path | None = None
    fps: float | None = None
    #: with ``video``: its frames used (``--every``, ``--max-frames``); ``images`` then
    #: holds the video file
    every: int = 1
    max_frames: int | None = None
    #: with ``video`` or ``bag``: skip blurred frames, and views that barely change
    #: (``--skip-blurred``, ``--min-change``)
    skip_blurred: bool = False
    min_change: float | None = None
    #: with ``bag``: the image topic (``images`` then holds the bag)
    topic: str | None = None
    #: with ``poses``: the file holds ``T_cam_world`` (a robot's ``T_flange_base``): inverted
    #: on reading
    invert: bool = False


@dataclass(frozen=True)
class RigJointSpec:
    """One joint of a rig config, with an optional prior on its position (metres)."""

    name: str
    between: tuple[str, str]
    type: str
    position_in: dict[str, np.ndarray] = field(default_factory=dict)
    position_std: float | None = None
    fixed_joint: dict[str, Path] = field(default_factory=dict)
    #: a hinge's axis sign: ``(body, direction)`` (acute with the direction in that body's
    #: frame) or ``towards`` a body (pointing from the joint to its origin); None: the
    #: default (largest component in the first body positive)
    axis_direction: tuple[str, np.ndarray] | None = None
    axis_towards: str | None = None
    #: a hinge's reported point: ``(body, point)``, the axis point nearest ``point`` (in
    #: that body's frame, the rig's length unit); None: the default (nearest the first
    #: body's origin)
    point_nearest: tuple[str, np.ndarray] | None = None


@dataclass(frozen=True)
class RigRecordingSpec:
    """One recording of a rig config: the bodies it saw, and whether they share a world.

    ``fixed_joints``: joints held still in the recording's world (the paper's fixed-joint
    motion, a pivot): each camera of such a joint gives the joint's position in its frame
    by Algorithm II, a prior of the rig solve; the recording adds no rows to those joints.
    """

    name: str
    cameras: dict[str, RigCameraSpec]
    shared_world: bool = False
    fixed_joints: tuple[str, ...] = ()


@dataclass(frozen=True)
class RigRunConfig:
    """A checked rig run configuration (``schema_version: 2``); paths are resolved."""

    path: Path
    output: Path
    reference_camera: str
    reference_frame: int
    cameras: dict[str, RigCameraSpec]
    joints: dict[str, RigJointSpec]
    topology: RigTopology
    board: tuple[int, int, float] | None = None
    #: an AprilGrid or ChArUco (config key ``target``) instead of the board
    target: MarkerTarget | None = None
    pair_by: str = "auto"
    max_dt: float | None = None
    workers: int | None = None
    bundle: bool = True
    estimate_time_offset: bool = False
    max_offset: float = 0.5
    #: options of the cameras with ``front_end: sfm`` (``acscal poses --sfm``'s)
    sfm: dict[str, Any] = field(default_factory=dict)
    #: write joints past a refusal level, marked weak (``acscal run --accept-weak``)
    accept_weak: bool = False
    #: every recording of the rig (one, named ``default``, for a config without
    #: ``recordings``); ``cameras`` holds each body's settings, common to its recordings
    recordings: dict[str, RigRecordingSpec] = field(default_factory=dict)
    reference_recording: str = DEFAULT_RECORDING

    def __post_init__(self) -> None:
        if not self.recordings:  # built by hand with cameras only: their one recording
            rec = RigRecordingSpec(DEFAULT_RECORDING, dict(self.cameras))
            object.__setattr__(self, "recordings", {DEFAULT_RECORDING: rec})
            object.__setattr__(self, "reference_recording", DEFAULT_RECORDING)

    @property
    def single(self) -> bool:
        """Whether the config has one recording."""
        return len(self.recordings) <= 1

    def recording_of_reference(self) -> RigRecordingSpec:
        """The reference recording's spec."""
        return self.recordings[self.reference_recording]


# --------------------------------------------------------------------------- value types

#: The type of custom errors: their message is the problem, as the user reads it.
_ERROR = "acscal"
#: Union tags, left out of the key a message names.
_TAGS = ("<path>", "<mapping>")


def _describe(value: Any) -> str:
    if value is None:
        return "nothing (null)"
    return f"{type(value).__name__} {short_repr(value, 40)}"


def _say(problem: str) -> WrapValidator:
    """Replace any error of the value it annotates by ``problem`` (``{got}``: the value)."""

    def wrap(value: Any, handler: ValidatorFunctionWrapHandler) -> Any:
        try:
            return handler(value)
        except ValidationError:
            raise PydanticCustomError(_ERROR, problem, {"got": _describe(value)}) from None

    return WrapValidator(wrap)


if TYPE_CHECKING:  # the choices are the tuples above, so that they are named once
    LensModel = str
    Method = str
    Scenario = str
    IntrinsicsFrom = str
    Scale = str
    FrontEnd = str
    SfmMatching = str
    TrajectoryFormat = str
    World = str
    PairBy = str
    JointType = str
    Schema = str
else:
    LensModel = Literal[MODELS]
    Method = Literal[METHODS]
    Scenario = Literal[JOINT_SCENARIOS]
    IntrinsicsFrom = Literal[INTRINSICS_FROM]
    Scale = Literal[SCALES]
    FrontEnd = Literal[FRONT_ENDS]
    SfmMatching = Literal[SFM_MATCHING]
    TrajectoryFormat = Literal[TRAJECTORY_FORMATS]
    World = Literal[WORLDS]
    PairBy = Literal[PAIR_BY]
    JointType = Literal[JOINT_TYPES]
    Schema = Literal[CONFIG_SCHEMA]

#: A path: resolved against the config's folder, ``~`` expanded.
ConfigPath = Annotated[
    str,
    Field(pattern=r"\S", description="a path; relative to the config file's folder"),
    _say("must be a path (a string), got {got}"),
]
#: A camera's, joint's or recording's name.
Name = Annotated[str, _say("must be a name (a string), got {got}")]
#: A number > 0 (an integer is taken).
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Workers = Annotated[int, Field(ge=1, description="detection processes (null: all cores)")]
#: A number of frames, at least 1.
Frames = Annotated[int, Field(ge=1)]
BoardCorners = Annotated[int, Field(ge=2, le=MAX_BOARD_CORNERS)]
SfmSize = Annotated[int, Field(ge=16)]
Vector3 = Annotated[
    list[Annotated[float, Field(allow_inf_nan=False)]],
    Field(min_length=3, max_length=3),
    _say("must be three numbers (m)"),
]
Point3 = Annotated[
    list[Annotated[float, Field(allow_inf_nan=False)]],
    Field(min_length=3, max_length=3),
    _say("must be three numbers (the rig's length unit)"),
]


def _path_or_mapping(value: Any) -> str:
    return "<mapping>" if isinstance(value, dict) else "<path>"


#: ``intrinsics_from``: a run folder, or one intrinsics file per camera.
PathOrFiles = Annotated[
    Annotated[ConfigPath, Tag("<path>")] | Annotated[dict[str, ConfigPath], Tag("<mapping>")],
    Discriminator(_path_or_mapping),
]
#: ``target``: a target mapping, a short form (``aprilgrid:6x6:0.088:0.3``) or a file.
_TargetText = Annotated[
    str,
    Field(pattern=r"\S", description="a short form or a target YAML file"),
    _say("must be a target mapping, a short form or a path (a string), got {got}"),
    Tag("<path>"),
]
_TargetMapping = Annotated[dict[str, Any], Field(description="as a target YAML"), Tag("<mapping>")]
TargetValue = Annotated[_TargetText | _TargetMapping, Discriminator(_path_or_mapping)]


class Section(BaseModel):
    """A mapping of the config: strict types, no unknown key, read-only."""

    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)

    def given(self, key: str) -> bool:
        """Whether the file gives ``key`` (not null)."""
        return key in self.model_fields_set and getattr(self, key) is not None


# --------------------------------------------------------------------------- version 1


class Board(Section):
    """A checkerboard: its inner corners and the square's side (m)."""

    cols: BoardCorners = Field(description="inner corners along the board's x axis")
    rows: BoardCorners = Field(description="inner corners along the board's y axis")
    square: Positive = Field(le=10.0, description="the square's side, metres (at most 10)")


class FrameSource(Section):
    """The keys a camera entry of either config version takes with a video or a bag (its
    ``video`` or ``images`` key is the entry's own: what it replaces differs)."""

    every: Frames | None = Field(
        default=None, description="with video or bag: use every n-th frame"
    )
    max_frames: Frames | None = Field(
        default=None, description="with video or bag: at most this many frames, spread evenly"
    )
    skip_blurred: bool | None = Field(
        default=None,
        description="with video or bag: skip frames whose sharpness is below half the median "
        "of the last 15 selected frames",
    )
    min_change: float | None = Field(
        default=None,
        gt=0.0,
        lt=1.0,
        description="with video or bag: skip frames that differ from the last kept one by less "
        "than this share of the grey range",
    )
    bag: ConfigPath | None = Field(
        default=None, description="instead of images: a ROS bag (ROS 1 .bag, ROS 2 folder, .mcap)"
    )
    topic: Name | None = Field(default=None, description="with bag: the image topic")


class RunCamera(FrameSource):
    """Camera ``a`` or ``b`` (may be empty)."""

    images: ConfigPath | None = Field(default=None, description="the folder of joint-motion images")
    video: ConfigPath | None = Field(
        default=None, description="instead of images: a video file of the joint motion"
    )
    model: LensModel = "pinhole"
    timestamps: ConfigPath | None = Field(default=None, description="image times (a CSV file)")
    fps: Positive | None = Field(default=None, description="image times from a frame rate")


class RunCameras(Section):
    a: RunCamera | None
    b: RunCamera | None = Field(default=None, description="required by relpose and joint overlap")


class IntrinsicsOptions(Section):
    from_: IntrinsicsFrom = Field(default="all", alias="from")


class JointStage(Section):
    """The joint stage (Algorithm I or II)."""

    scenario: Scenario
    method: Method = "refined"
    bundle: bool = True
    joint_type: JointType = Field(
        default="ball",
        description="overlap, refined method: the joint is a ball or a hinge (rigid: no joint "
        "point to locate; calibrate it with relpose)",
    )


class RelposeImages(Section):
    a: ConfigPath
    b: ConfigPath


class RelposeStage(Section):
    """The relative-pose stage (Algorithms III, IV, self-calibration)."""

    images: RelposeImages
    method: Method = "refined"
    unknown_scale: bool = False
    self_calibrate: bool = False
    reference: int = Field(default=0, ge=0)
    bundle: bool = True
    joint_type: JointType = Field(
        default="ball",
        description="refined method: the joint is a ball, a hinge or rigid (a constant T_b_a: "
        "no joint section, no self_calibrate needed)",
    )


class RunConfigFile(Section):
    """A run config, version 1: cameras ``a`` and ``b``, the joint and relpose stages."""

    model_config = ConfigDict(title="acscal run config (version 1)")

    schema_: Schema = Field(alias="schema")
    schema_version: int = Field(ge=1, json_schema_extra={"const": CONFIG_VERSION})
    output: ConfigPath
    board: Board | None = None
    target: TargetValue | None = None
    cameras: RunCameras
    intrinsics_from: PathOrFiles | None = None
    intrinsics: IntrinsicsOptions | None = None
    joint: JointStage | None = None
    relpose: RelposeStage | None = None
    workers: Workers | None = None


# --------------------------------------------------------------------------- version 2


class RigCamera(FrameSource):
    """One camera (body) of a rig: a trajectory file or a folder of images."""

    poses: ConfigPath | None = Field(default=None, description="a trajectory of T_world_cam")
    format: TrajectoryFormat = "auto"
    images: ConfigPath | None = Field(default=None, description="instead of poses: an image folder")
    video: ConfigPath | None = Field(default=None, description="instead of poses: a video file")
    model: LensModel = "pinhole"
    scale: Scale | None = Field(default=None, description="default known (unknown with sfm)")
    front_end: FrontEnd = "board"
    intrinsics: ConfigPath | None = Field(default=None, description="with front_end: sfm")
    timestamps: ConfigPath | None = None
    fps: Positive | None = None
    invert: bool = Field(
        default=False,
        description="with poses: the file holds T_cam_world (e.g. a robot's T_flange_base), "
        "inverted on reading",
    )


class Recording(Section):
    """One recording of a rig: the bodies it saw."""

    cameras: dict[str, RigCamera | None]
    world: World = "separate"
    fixed_joints: Annotated[list[str], _say("must be a list of joint names")] | None = Field(
        default=None, description="joints held still in this recording"
    )


class Reference(Section):
    camera: Name | None = Field(default=None, description="default: the first camera")
    frame: int = Field(default=0, ge=0)
    recording: Name | None = Field(default=None, description="default: the first recording")


class AxisConvention(Section):
    """Which way a hinge's axis points: ``direction`` in body ``in``'s frame (the axis makes
    an acute angle with it), or ``towards`` a named body (the axis points from the joint
    towards that body's origin at the reference instant)."""

    direction: Vector3 | None = Field(default=None, description="a direction, in body 'in'")
    in_: Name | None = Field(default=None, alias="in", description="one of the joint's bodies")
    towards: Name | None = Field(default=None, description="a body of the rig")


class PointConvention(Section):
    """Where a hinge's point is reported: the axis point nearest ``nearest``, a point in
    body ``in``'s frame (the rig's length unit: the reference camera's trajectory unit)."""

    nearest: Point3 = Field(description="a point, in body 'in' (the rig's length unit)")
    in_: Name = Field(alias="in", description="one of the joint's bodies")


class Joint(Section):
    """A joint between two cameras."""

    between: Annotated[
        list[str], Field(min_length=2, max_length=2), _say("must be a list of two camera names")
    ]
    type: JointType
    position_in: dict[str, Vector3] | None = Field(default=None, description="a prior, metres")
    position_std: Positive | None = Field(default=None, description="the prior's one-sigma, metres")
    fixed_joint: dict[str, ConfigPath] | None = Field(
        default=None, description="a fixed-joint session (a trajectory) per camera"
    )
    axis: AxisConvention | None = Field(
        default=None,
        description="hinge: which way its axis points (default: largest component in the "
        "first body positive)",
    )
    point: PointConvention | None = Field(
        default=None,
        description="hinge: where its point is reported (default: the axis point nearest the "
        "first body's origin)",
    )


class SfmOptions(Section):
    """Options of the ``front_end: sfm`` cameras (``acscal poses --sfm``'s)."""

    matching: SfmMatching | None = None
    loop_closure: bool | None = None
    refine_intrinsics: bool | None = None
    max_features: SfmSize | None = None
    max_image_size: SfmSize | None = None


class RigConfigFile(Section):
    """A rig run config, version 2: named cameras (or recordings) and joints."""

    model_config = ConfigDict(title="acscal rig config (version 2)")

    schema_: Schema = Field(default=CONFIG_SCHEMA, alias="schema")
    schema_version: int = Field(
        default=RIG_CONFIG_VERSION, ge=1, json_schema_extra={"const": RIG_CONFIG_VERSION}
    )
    output: ConfigPath
    reference: Reference | None = None
    world: World | None = Field(default=None, description="without recordings (default separate)")
    cameras: dict[str, RigCamera | None] | None = None
    recordings: dict[str, Recording] | None = None
    joints: dict[str, Joint]
    board: Board | None = None
    target: TargetValue | None = None
    pair_by: PairBy = "auto"
    max_dt: Positive | None = None
    workers: Workers | None = None
    bundle: bool = True
    estimate_time_offset: bool = False
    max_offset: Positive = 0.5
    sfm: SfmOptions | None = None


# --------------------------------------------------------------------------- errors


def _fail(path: Path, key: str, problem: str) -> InputError:
    return InputError(f"key '{key}': {problem}", path=path)


def _loc(err: ErrorDetails) -> tuple[str | int, ...]:
    return tuple(x for x in err["loc"] if x not in _TAGS)


def _unwrap(tp: Any) -> Any:
    """A field's type without ``None`` (``X | None`` is ``X``)."""
    args = [a for a in getattr(tp, "__args__", ()) if a is not type(None)]
    if type(None) in getattr(tp, "__args__", ()) and len(args) == 1:
        return args[0]
    return tp


def _section_at(model: type[BaseModel], loc: tuple[str | int, ...]) -> type[BaseModel] | None:
    """The model of the mapping at ``loc`` (its keys are its fields), or None."""
    tp: Any = model
    for item in loc:
        tp = _unwrap(tp)
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            fields = {f.alias or n: f for n, f in tp.model_fields.items()}
            if item not in fields:
                return None
            tp = fields[str(item)].annotation
        elif getattr(tp, "__origin__", None) in (dict, list):
            tp = tp.__args__[-1]
        else:
            return None
    tp = _unwrap(tp)
    return tp if isinstance(tp, type) and issubclass(tp, BaseModel) else None


#: Which of several errors is named: the shallowest key; there, an unknown key first.
_RANK = {"extra_forbidden": 0, "missing": 1}


def _one_line(exc: ValidationError, model: type[BaseModel], path: Path) -> InputError:
    """The first of pydantic's errors as one :class:`InputError` naming the key."""
    errors = sorted(exc.errors(), key=lambda e: (len(_loc(e)), _RANK.get(e["type"], 2)))
    err = errors[0]
    loc = _loc(err)
    if loc and loc[-1] == "[key]":
        key = ".".join(map(str, loc[:-1]))
        return _fail(path, key, f"a name must be a string, got {_describe(err['input'])}")
    return _fail(path, ".".join(map(str, loc)), _problem(err, model, loc))


def _problem(err: ErrorDetails, model: type[BaseModel], loc: tuple[str | int, ...]) -> str:
    kind, value, ctx = err["type"], err["input"], err.get("ctx", {})
    if kind == _ERROR:
        return err["msg"]
    if kind == "extra_forbidden":
        section = _section_at(model, loc[:-1])
        known = sorted(f.alias or n for n, f in section.model_fields.items()) if section else []
        return f"unknown key (known keys: {', '.join(known)})"
    if kind == "missing":
        return "missing (required)"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return f"must be a mapping, got {_describe(value)}"
    if kind == "literal_error":
        choices = re.findall(r"'([^']*)'", str(ctx.get("expected", "")))
        return f"must be one of {', '.join(choices)}; got {value!r}"
    if kind == "int_type":
        return f"must be an integer, got {_describe(value)}"
    if kind == "float_type":
        return f"must be a number, got {_describe(value)}"
    if kind == "bool_type":
        return f"must be true or false, got {_describe(value)}"
    if kind in ("greater_than", "finite_number"):
        return f"must be a positive number, got {value}"
    if kind == "greater_than_equal":
        return f"must be at least {ctx['ge']}, got {value}"
    if kind == "less_than_equal":
        what = " inner corners" if loc[-1] in ("cols", "rows") else ""
        return f"at most {ctx['le']}{what}, got {value}"
    if kind == "string_type":
        return f"must be a string, got {_describe(value)}"
    if kind == "list_type":
        return f"must be a list, got {_describe(value)}"
    return f"{err['msg'][:1].lower()}{err['msg'][1:]}, got {_describe(value)}"


def _validate(model: type[BaseModel], doc: Any, path: Path) -> Any:
    try:
        return model.model_validate(doc)
    except ValidationError as exc:
        raise _one_line(exc, model, path) from None


# --------------------------------------------------------------------------- shared rules


def _resolve(value: str, path: Path) -> Path:
    """A config path: ``~`` expanded, relative to the config file's folder."""
    p = Path(os.path.expanduser(value))
    return Path(os.path.normpath(p if p.is_absolute() else path.parent / p))


def _opt_path(value: str | None, path: Path) -> Path | None:
    return None if value is None else _resolve(value, path)


def _board_or_target(
    m: RunConfigFile | RigConfigFile, path: Path
) -> tuple[tuple[int, int, float] | None, MarkerTarget | None]:
    """The config's ``board`` or ``target`` (not both): a checkerboard (named either way)
    as ``(cols, rows, square)``, an AprilGrid or ChArUco as the target."""
    from acs_cli.core.targets import Checkerboard
    from acs_cli.io.target import parse_target_short, read_target_yaml, target_from_mapping

    if m.board is not None and m.target is not None:
        raise _fail(path, "target", "give either 'board' or 'target', not both")
    if m.target is None:
        return (None if m.board is None else (m.board.cols, m.board.rows, m.board.square)), None
    value = m.target
    if isinstance(value, dict):
        target = target_from_mapping(value, path, "target")
    elif ":" in value:
        target = parse_target_short(value, option=f"{path}: key 'target'")
    else:
        target = read_target_yaml(_resolve(value, path))
    if isinstance(target, Checkerboard):
        return (target.cols, target.rows, target.square), None
    return None, target


def _camera_times(cam: RunCamera | RigCamera, key: str, path: Path) -> None:
    if cam.given("timestamps") and cam.given("fps"):
        raise _fail(path, key, "give either 'timestamps' or 'fps', not both")


def _frames_path(cam: RunCamera | RigCamera) -> str | None:
    """The camera's images, video or bag (one at most is given)."""
    return cam.video or cam.bag or cam.images


def _camera_video(cam: RunCamera | RigCamera, key: str, path: Path) -> None:
    """``images``, ``video`` and ``bag`` exclude each other; a video's or bag's frames carry
    their times; ``every``, ``max_frames``, ``skip_blurred`` and ``min_change`` go with
    ``video`` or ``bag``, ``topic`` with
    ``bag`` (which needs it)."""
    given = [k for k in ("images", "video", "bag") if cam.given(k)]
    if len(given) > 1:
        raise _fail(path, key, f"give one of {' and '.join(repr(k) for k in given)}, not both")
    if cam.given("video") or cam.given("bag"):
        for k in ("timestamps", "fps"):
            if cam.given(k):
                raise _fail(
                    path,
                    f"{key}.{k}",
                    "goes with 'images': a video's or bag's frames carry their own times",
                )
    elif any(cam.given(k) for k in _VIDEO_KEYS):
        raise _fail(
            path, key, f"{', '.join(repr(k) for k in _VIDEO_KEYS)} go with 'video' or 'bag'"
        )
    if cam.given("bag") and not cam.given("topic"):
        raise _fail(path, f"{key}.topic", "missing (a bag needs its image topic)")
    if cam.given("topic") and not cam.given("bag"):
        raise _fail(path, f"{key}.topic", "goes with 'bag' (a ROS bag)")


def _unknown_keys(keys: Iterable[str], known: Iterable[str], key: str, path: Path) -> None:
    allowed = list(known)
    for k in keys:
        if k not in allowed:
            raise _fail(
                path, f"{key}.{k}", f"unknown key (known keys: {', '.join(sorted(allowed))})"
            )


# --------------------------------------------------------------------------- parsing


def is_rig_config(doc: Any) -> bool:
    """Whether a loaded run config is a rig config (version 2, or it has ``joints``)."""
    return isinstance(doc, dict) and (
        doc.get("schema_version") == RIG_CONFIG_VERSION or "joints" in doc
    )


def load_run_config(path: Path) -> RunConfig | RigRunConfig:
    """Read a run configuration file and check it.

    A config with ``joints`` (``schema_version: 2``) is a rig of named cameras
    (:func:`parse_rig_config`); version 1 (cameras ``a`` and ``b``) is checked by
    :func:`parse_run_config`.

    Raises
    ------
    InputError
        A missing or unreadable file, bad YAML, or a bad key.
    """
    p = Path(path)
    doc = load_yaml_file(p, "a run config (YAML)")
    if is_rig_config(doc):
        return parse_rig_config(doc, p)
    return parse_run_config(doc, p)


def parse_run_config(doc: Any, path: Path) -> RunConfig:
    """Check a loaded run configuration (version 1) and resolve its paths against
    ``path``'s folder.

    Raises
    ------
    InputError
        An unknown key, a missing required key, or a value of the wrong type or range; the
        message names the file and the dotted key.
    """
    if isinstance(doc, dict) and doc.get("schema", CONFIG_SCHEMA) != CONFIG_SCHEMA:
        raise _fail(
            path,
            "schema",
            f"must be {CONFIG_SCHEMA}, got {str(doc['schema'])[:60]!r}: not a run config",
        )
    m: RunConfigFile = _validate(RunConfigFile, doc, path)
    if m.schema_version > CONFIG_VERSION:
        raise _fail(
            path,
            "schema_version",
            f"{m.schema_version} is newer than this acscal reads ({CONFIG_VERSION}); "
            "upgrade acscal",
        )
    board, target = _board_or_target(m, path)
    if board is None and target is None:
        raise _fail(path, "board", "missing (required, or a 'target')")
    cols, rows, square = board or _UNUSED_BOARD

    cameras: dict[str, CameraSpec] = {}
    for name in CAMERAS:
        if name not in m.cameras.model_fields_set:
            continue
        cam = getattr(m.cameras, name) or RunCamera()
        _camera_times(cam, f"cameras.{name}", path)
        _camera_video(cam, f"cameras.{name}", path)
        cameras[name] = CameraSpec(
            name,
            _opt_path(_frames_path(cam), path),
            cam.model,
            _opt_path(cam.timestamps, path),
            cam.fps,
            every=cam.every or 1,
            max_frames=cam.max_frames,
            skip_blurred=bool(cam.skip_blurred),
            min_change=cam.min_change,
            topic=cam.topic,
        )

    intrinsics_from: dict[str, Path] | None = None
    if isinstance(m.intrinsics_from, dict):
        _unknown_keys(m.intrinsics_from, cameras, "intrinsics_from", path)
        intrinsics_from = {
            n: _resolve(m.intrinsics_from[n], path) for n in cameras if n in m.intrinsics_from
        }
        missing = [n for n in cameras if n not in intrinsics_from]
        if missing:
            raise _fail(path, f"intrinsics_from.{missing[0]}", "missing (one file per camera)")
    elif m.intrinsics_from is not None:
        run_dir = _resolve(m.intrinsics_from, path)
        intrinsics_from = {n: run_dir / f"cam_{n}" / "intrinsics.yaml" for n in cameras}
    intrinsics_images = "all" if m.intrinsics is None else m.intrinsics.from_

    joint: JointSpec | None = None
    if m.joint is not None:
        joint = JointSpec(m.joint.scenario, m.joint.method, m.joint.bundle, m.joint.joint_type)
        if joint.joint_type != "ball":
            if joint.scenario != "overlap":
                raise _fail(path, "joint.joint_type", "only for scenario overlap")
            if joint.joint_type == "rigid":
                raise _fail(
                    path,
                    "joint.joint_type",
                    "rigid has no joint point to locate: remove the 'joint' section and set "
                    "relpose.joint_type: rigid",
                )
            if joint.method == "paper":
                raise _fail(path, "joint.joint_type", "the paper's method is ball only")
        for name, spec in cameras.items():
            if spec.images is None:
                raise _fail(path, f"cameras.{name}.images", "missing (the joint stage needs it)")
        if joint.scenario == "overlap" and "b" not in cameras:
            raise _fail(path, "cameras.b", "missing (joint.scenario overlap needs both cameras)")

    relpose: RelposeSpec | None = None
    if m.relpose is not None:
        r = m.relpose
        if "b" not in cameras:
            raise _fail(path, "cameras.b", "missing (relpose needs both cameras)")
        relpose = RelposeSpec(
            images={n: _resolve(getattr(r.images, n), path) for n in CAMERAS},
            method=r.method,
            unknown_scale=r.unknown_scale,
            self_calibrate=r.self_calibrate,
            reference=r.reference,
            bundle=r.bundle,
            joint_type=r.joint_type,
        )
        if relpose.joint_type != "ball" and relpose.method == "paper":
            raise _fail(path, "relpose.joint_type", "the paper's method is ball only")
        if relpose.joint_type == "rigid" and joint is not None:
            raise _fail(
                path,
                "relpose.joint_type",
                "rigid has no joint point to take from the joint stage: remove the 'joint' section",
            )
        if relpose.self_calibrate and joint is not None:
            raise _fail(
                path,
                "relpose.self_calibrate",
                "true estimates the joint from the general motion: remove the 'joint' section",
            )
        if not relpose.self_calibrate and joint is None and relpose.joint_type != "rigid":
            raise _fail(
                path, "joint", "missing (relpose needs it, or relpose.self_calibrate: true)"
            )
    if joint is None and relpose is None:
        raise _fail(path, "joint", "missing: name a 'joint' section, a 'relpose' section or both")

    if intrinsics_from is None and intrinsics_images == "joint":
        for name, spec in cameras.items():
            if spec.images is None:
                raise _fail(
                    path,
                    "intrinsics.from",
                    f"'joint' but camera {name} has no joint images (cameras.{name}.images)",
                )
    return RunConfig(
        path=path,
        output=_resolve(m.output, path),
        cols=cols,
        rows=rows,
        square=square,
        cameras=cameras,
        intrinsics_from=intrinsics_from,
        target=target,
        intrinsics_images=intrinsics_images,
        joint=joint,
        relpose=relpose,
        workers=m.workers,
    )


def parse_rig_config(doc: Any, path: Path) -> RigRunConfig:
    """Check a rig run config (version 2); every error is an :class:`InputError` naming
    the key.

    Raises
    ------
    InputError
        Unknown or missing keys, wrong values, and a joint graph that is not a tree: a
        cycle, an unknown camera in a joint, two joints between one pair, a camera in no
        joint.
    """
    if isinstance(doc, dict) and doc.get("schema", CONFIG_SCHEMA) != CONFIG_SCHEMA:
        raise _fail(path, "schema", f"must be {CONFIG_SCHEMA}, got {str(doc['schema'])[:60]!r}")
    m: RigConfigFile = _validate(RigConfigFile, doc, path)
    if m.schema_version != RIG_CONFIG_VERSION:
        raise _fail(
            path,
            "schema_version",
            f"a config with joints is version {RIG_CONFIG_VERSION}, got {m.schema_version}",
        )
    if m.given("cameras") == m.given("recordings"):
        raise _fail(
            path, "cameras", "give either 'cameras' (one recording) or 'recordings' (several)"
        )
    recordings: dict[str, RigRecordingSpec] = {}
    if m.cameras is not None:
        cams = _camera_specs(m.cameras, "cameras", path)
        recordings[DEFAULT_RECORDING] = RigRecordingSpec(
            DEFAULT_RECORDING, cams, m.world == "shared"
        )
    else:
        if m.given("world"):
            raise _fail(path, "world", "goes in each recording (recordings.<name>.world)")
        if not m.recordings:
            raise _fail(path, "recordings", "names no recording")
        for rname, rec in m.recordings.items():
            key = f"recordings.{rname}"
            recordings[rname] = RigRecordingSpec(
                rname,
                _camera_specs(rec.cameras, f"{key}.cameras", path),
                rec.world == "shared",
                tuple(rec.fixed_joints or ()),
            )
    cameras = _body_settings(recordings, path)
    ref = m.reference or Reference()
    ref_rec = ref.recording if ref.recording is not None else next(iter(recordings))
    if ref_rec not in recordings:
        raise _fail(
            path,
            "reference.recording",
            f"must name one of the recordings ({', '.join(recordings)})",
        )
    ref_cam = ref.camera if ref.camera is not None else next(iter(recordings[ref_rec].cameras))
    if ref_cam not in cameras:
        raise _fail(
            path, "reference.camera", f"must name one of the cameras ({', '.join(cameras)})"
        )
    if ref_cam not in recordings[ref_rec].cameras:
        raise _fail(
            path, "reference.camera", f"{ref_cam} is not in the reference recording {ref_rec}"
        )
    joints = {name: _joint_spec(name, j, list(cameras), path) for name, j in m.joints.items()}
    if not joints:
        raise _fail(
            path, "joints", "names no joint: a rig needs two cameras and a joint between them"
        )
    raw = [(j.name, list(j.between), j.type) for j in joints.values()]
    try:
        topo = rig_topology(list(cameras), raw, ref_cam)
    except InputError as exc:
        raise InputError(exc.message, path=path) from None
    _check_recordings(recordings, joints, path)
    board, target = _board_or_target(m, path)
    image_cams = [n for n, s in cameras.items() if s.images is not None and s.front_end == "board"]
    if image_cams and board is None and target is None:
        raise _fail(path, "board", f"missing (camera {image_cams[0]} has images; or a 'target')")
    sfm = {} if m.sfm is None else m.sfm.model_dump(exclude_none=True)
    return RigRunConfig(
        path=path,
        output=_resolve(m.output, path),
        reference_camera=ref_cam,
        reference_frame=ref.frame,
        cameras=cameras,
        joints=joints,
        topology=topo,
        board=board,
        target=target,
        pair_by=m.pair_by,
        max_dt=m.max_dt,
        workers=m.workers,
        bundle=m.bundle,
        estimate_time_offset=m.estimate_time_offset,
        max_offset=m.max_offset,
        sfm=sfm,
        recordings=recordings,
        reference_recording=ref_rec,
    )


def _camera_specs(
    doc: dict[str, RigCamera | None], where: str, path: Path
) -> dict[str, RigCameraSpec]:
    """The camera entries of one recording (``cameras`` or ``recordings.<r>.cameras``)."""
    if not doc:
        raise _fail(path, where, "names no camera")
    cameras: dict[str, RigCameraSpec] = {}
    for name, entry in doc.items():
        key = f"{where}.{name}"
        cam = entry or RigCamera()
        if [cam.given(k) for k in ("poses", "images", "video", "bag")].count(True) != 1:
            raise _fail(
                path,
                key,
                "give one of 'poses' (a trajectory file), 'images' (a folder), 'video' "
                "(a video file) or 'bag' (a ROS bag)",
            )
        if not (cam.given("images") or cam.given("video") or cam.given("bag")) and any(
            cam.given(k) for k in _IMAGE_KEYS
        ):
            raise _fail(
                path,
                key,
                f"{', '.join(repr(k) for k in _IMAGE_KEYS)} go with 'images', 'video' or 'bag'",
            )
        _camera_times(cam, key, path)
        _camera_video(cam, key, path)
        if cam.invert and not cam.given("poses"):
            raise _fail(path, f"{key}.invert", "goes with 'poses' (a trajectory file)")
        if cam.front_end == "board" and cam.given("intrinsics"):
            raise _fail(
                path, f"{key}.intrinsics", "is for front_end: sfm (a board calibrates them)"
            )
        scale = cam.scale or ("unknown" if cam.front_end == "sfm" else "known")
        if cam.front_end == "sfm" and scale == "known":
            raise _fail(
                path,
                f"{key}.scale",
                "structure from motion gives trajectories up to scale: unknown",
            )
        cameras[name] = RigCameraSpec(
            name=name,
            poses=_opt_path(cam.poses, path),
            format=cam.format,
            images=_opt_path(_frames_path(cam), path),
            model=cam.model,
            unknown_scale=scale == "unknown",
            front_end=cam.front_end,
            intrinsics=_opt_path(cam.intrinsics, path),
            timestamps=_opt_path(cam.timestamps, path),
            fps=cam.fps,
            every=cam.every or 1,
            max_frames=cam.max_frames,
            skip_blurred=bool(cam.skip_blurred),
            min_change=cam.min_change,
            topic=cam.topic,
            invert=cam.invert,
        )
    return cameras


def _joint_spec(name: str, j: Joint, bodies: list[str], path: Path) -> RigJointSpec:
    """One joint of a rig config (its graph is checked by :func:`rig_topology`); ``bodies``:
    the rig's."""
    key = f"joints.{name}"
    between = (j.between[0], j.between[-1])
    pos: dict[str, np.ndarray] = {}
    if j.position_in is not None:
        _unknown_keys(j.position_in, between, f"{key}.position_in", path)
        pos = {c: np.asarray(v, dtype=float) for c, v in j.position_in.items()}
    if not joint_model(j.type).has_point and pos:
        raise _fail(path, f"{key}.position_in", f"a {j.type} joint has no position")
    fixed: dict[str, Path] = {}
    if j.fixed_joint is not None:
        if not joint_model(j.type).has_point:
            raise _fail(path, f"{key}.fixed_joint", f"a {j.type} joint has no fixed-joint session")
        _unknown_keys(j.fixed_joint, between, f"{key}.fixed_joint", path)
        fixed = {n: _resolve(v, path) for n, v in j.fixed_joint.items()}
    direction, towards = _axis_convention(key, j, between, bodies, path)
    nearest = _point_convention(key, j, between, path)
    return RigJointSpec(
        name, between, j.type, pos, j.position_std, fixed, direction, towards, nearest
    )


def _point_convention(
    key: str, j: Joint, between: tuple[str, str], path: Path
) -> tuple[str, np.ndarray] | None:
    """A joint's ``point`` (:class:`PointConvention`), checked: ``(body, point)``."""
    pt = j.point
    if pt is None:
        return None
    if not joint_model(j.type).has_axis:
        what = (
            f"a {j.type} joint's point is its centre, not a choice"
            if joint_model(j.type).has_point
            else f"a {j.type} joint has no point"
        )
        raise _fail(path, f"{key}.point", f"{what}: only a hinge's point is chosen, along its axis")
    if pt.in_ not in between:
        raise _fail(path, f"{key}.point.in", f"must be one of the joint's bodies {list(between)}")
    return pt.in_, np.asarray(pt.nearest, dtype=float)


def _axis_convention(
    key: str, j: Joint, between: tuple[str, str], bodies: list[str], path: Path
) -> tuple[tuple[str, np.ndarray] | None, str | None]:
    """A joint's ``axis`` (:class:`AxisConvention`), checked: ``(body, direction)`` or
    ``towards``."""
    a = j.axis
    if a is None:
        return None, None
    if not joint_model(j.type).has_axis:
        raise _fail(path, f"{key}.axis", f"a {j.type} joint has no axis")
    if a.towards is not None:
        if a.direction is not None or a.in_ is not None:
            raise _fail(path, f"{key}.axis", "give 'direction' with 'in', or 'towards', not both")
        if a.towards not in bodies:
            raise _fail(
                path,
                f"{key}.axis.towards",
                f"must name one of the rig's bodies ({', '.join(bodies)})",
            )
        if a.towards == between[0]:
            # the hinge's point is the axis point nearest that body's centre: seen from it,
            # the body lies across the axis, which tells no sign
            raise _fail(
                path,
                f"{key}.axis.towards",
                f"{between[0]} lies across the axis (the joint's point is the axis point "
                f"nearest its centre): name another body ({between[1]}, or any of the rig)",
            )
        return None, a.towards
    if a.direction is None or a.in_ is None:
        raise _fail(path, f"{key}.axis", "give 'direction' with 'in' (a body), or 'towards'")
    if a.in_ not in between:
        raise _fail(path, f"{key}.axis.in", f"must be one of the joint's bodies {list(between)}")
    d = np.asarray(a.direction, dtype=float)
    if not float(np.linalg.norm(d)) > 0:
        raise _fail(path, f"{key}.axis.direction", "must not be zero")
    return (a.in_, d), None


def _body_settings(recordings: dict[str, RigRecordingSpec], path: Path) -> dict[str, RigCameraSpec]:
    """Each body's settings (its first recording's entry); a body whose recordings disagree
    on its scale, camera model, front end or intrinsics is refused naming the key."""
    out: dict[str, RigCameraSpec] = {}
    first: dict[str, str] = {}
    for rname, rec in recordings.items():
        for name, spec in rec.cameras.items():
            if name not in out:
                out[name], first[name] = spec, rname
                continue
            for k in _BODY_KEYS:
                if getattr(spec, k) != getattr(out[name], k):
                    what = "scale" if k == "unknown_scale" else k
                    raise _fail(
                        path,
                        f"recordings.{rname}.cameras.{name}.{what}",
                        f"differs from recordings.{first[name]}.cameras.{name}: a body's "
                        f"{what} is the same in every recording",
                    )
    return out


def _check_recordings(
    recordings: dict[str, RigRecordingSpec], joints: dict[str, RigJointSpec], path: Path
) -> None:
    """Every joint is seen moving by some recording with both its bodies (a recording that
    holds it still gives its position, not the rig's articulation); every held joint exists,
    is not rigid and is seen by its recording."""
    determined = set()
    for rname, rec in recordings.items():
        key = f"recordings.{rname}.fixed_joints"
        for h in rec.fixed_joints:
            if h not in joints:
                raise _fail(path, key, f"{h!r} is not a joint")
            if not joint_model(joints[h].type).has_point:
                raise _fail(path, key, f"{h} is {joints[h].type}: it cannot be held still")
            if not any(b in rec.cameras for b in joints[h].between):
                raise _fail(path, key, f"the recording sees neither body of {h}")
        for jn, j in joints.items():
            if all(b in rec.cameras for b in j.between) and jn not in rec.fixed_joints:
                determined.add(jn)
    for jn in joints:
        if jn not in determined:
            raise _fail(
                path,
                f"joints.{jn}",
                "no recording sees both of its bodies move (one that holds it still gives "
                "its position, not how the bodies turn): add a recording of it moving",
            )


# --------------------------------------------------------------------------- JSON Schema


def json_schema() -> dict[str, Any]:
    """The JSON Schema of a run config, either version (``docs/run-config.schema.json``)."""
    adapter: TypeAdapter[Any] = TypeAdapter(RunConfigFile | RigConfigFile)
    body = adapter.json_schema(by_alias=True)
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "acscal run config",
        "description": (
            "acscal run CONFIG: version 1 (cameras a and b, the joint and relpose stages) or "
            "version 2 (a rig: named cameras or recordings, and joints). Generated by "
            "`python -m acs_cli.io.config --schema`; see docs/formats.md."
        ),
        **body,
    }


def _main(argv: list[str], write: Callable[[str], Any]) -> int:
    if argv != ["--schema"]:
        write("usage: python -m acs_cli.io.config --schema > docs/run-config.schema.json\n")
        return 2
    write(json.dumps(json_schema(), indent=2, sort_keys=False) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(_main(sys.argv[1:], sys.stdout.write))
