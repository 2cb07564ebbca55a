"""The run config's models (``acs_cli/io/config.py``): the published JSON Schema is theirs,
and every bad value is one line naming its key (never a crash)."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from acs_cli.errors import InputError
from acs_cli.io.config import _main, json_schema, load_run_config, parse_rig_config

REPO = Path(__file__).resolve().parents[2]
SCHEMA_FILE = REPO / "docs" / "run-config.schema.json"

RIG: dict[str, Any] = {
    "schema_version": 2,
    "output": "out",
    "board": {"cols": 9, "rows": 6, "square": 0.025},
    "cameras": {
        "cam0": {"poses": "c0.tum"},
        "cam1": {"poses": "c1.tum", "scale": "unknown"},
        "cam2": {"images": "imgs/c2", "fps": 25},
    },
    "joints": {
        "j01": {"between": ["cam0", "cam1"], "type": "ball", "position_in": {"cam0": [0, 0, 1]}},
        "j12": {"between": ["cam1", "cam2"], "type": "hinge"},
    },
}


def test_the_committed_schema_is_the_generated_one() -> None:
    """Regenerate with ``python -m acs_cli.io.config --schema > docs/run-config.schema.json``."""
    out: list[str] = []
    assert _main(["--schema"], out.append) == 0
    assert SCHEMA_FILE.read_text(encoding="utf-8") == "".join(out)
    assert json.loads("".join(out)) == json.loads(json.dumps(json_schema()))
    assert _main([], out.append) == 2


def test_the_schema_accepts_the_example_configs_and_refuses_a_typo() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    validator = jsonschema.Draft202012Validator(json.loads(SCHEMA_FILE.read_text()))
    for path in sorted((REPO / "configs").glob("*.yaml")):
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
        assert not list(validator.iter_errors(doc)), path
        load_run_config(path)  # and acscal agrees
    assert not list(validator.iter_errors(RIG))
    for key, value in (("scal", "unknown"), ("scale", "metric"), ("fps", -1)):
        bad = copy.deepcopy(RIG)
        bad["cameras"]["cam1"][key] = value
        assert list(validator.iter_errors(bad)), key


@pytest.mark.parametrize(
    ("change", "key", "says"),
    [
        ({"cameras": 5}, "cameras", "must be a mapping, got int 5"),
        ({"cameras.cam1.scale": "metric"}, "cameras.cam1.scale", "must be one of known, unknown"),
        ({"cameras.cam2.fps": "25"}, "cameras.cam2.fps", "must be a number, got str '25'"),
        ({"cameras.cam2.fps": True}, "cameras.cam2.fps", "must be a number, got bool True"),
        ({"workers": 1.0}, "workers", "must be an integer, got float 1.0"),
        ({"board.cols": 5000}, "board.cols", "at most 1000 inner corners, got 5000"),
        ({"joints.j12.between": []}, "joints.j12.between", "must be a list of two camera names"),
        ({"joints.j12.between": ["cam1"]}, "joints.j12.between", "two camera names"),
        ({"joints.j01.position_in.cam0": ["x", 0, 1]}, "joints.j01.position_in.cam0", "three"),
        ({"joints.j01.position_in.cam0": [0, 0, True]}, "joints.j01.position_in.cam0", "three"),
        ({"joints.j01.position_in.cam0": [0, 0, ".inf"]}, "joints.j01.position_in.cam0", "three"),
        ({"joints.j01.position_in.cam9": [0, 0, 1]}, "joints.j01.position_in.cam9", "unknown key"),
        ({"joints.j01.colour": 1}, "joints.j01.colour", "known keys: axis, between, fixed_joint"),
        ({"reference": {"camera": 3}}, "reference.camera", "must be a name (a string), got int 3"),
        ({"cameras.cam0": {"poses": "  "}}, "cameras.cam0.poses", "must be a path (a string)"),
        ({"sfm": {"max_features": 8}}, "sfm.max_features", "must be at least 16, got 8"),
        ({"max_dt": float("inf")}, "max_dt", "must be a positive number, got inf"),
    ],
)
def test_a_bad_rig_value_is_one_line_naming_its_key(
    tmp_path: Path, change: dict[str, Any], key: str, says: str
) -> None:
    doc = copy.deepcopy(RIG)
    for dotted, value in change.items():
        *parents, last = dotted.split(".")
        node = doc
        for p in parents:
            node = node[p]
        node[last] = value
    path = tmp_path / "rig.yaml"
    with pytest.raises(InputError) as info:
        parse_rig_config(doc, path)
    assert info.value.message.startswith(f"key '{key}': "), info.value.message
    assert says in info.value.message
    line = info.value.one_line()
    assert line.startswith(f"{path}: ") and "\n" not in line


def test_null_is_a_key_left_out(tmp_path: Path) -> None:
    doc = copy.deepcopy(RIG)
    doc["cameras"]["cam2"]["timestamps"] = None
    doc["reference"] = None
    doc["sfm"] = None
    cfg = parse_rig_config(doc, tmp_path / "rig.yaml")
    assert cfg.cameras["cam2"].timestamps is None and cfg.reference_camera == "cam0"
    assert cfg.sfm == {} and cfg.cameras["cam2"].images == tmp_path / "imgs" / "c2"


def test_a_camera_takes_a_video_with_its_frame_selection(tmp_path: Path) -> None:
    doc = copy.deepcopy(RIG)
    doc["cameras"]["cam2"] = {
        "video": "rec/c2.mp4",
        "every": 3,
        "max_frames": 40,
        "skip_blurred": True,
        "min_change": 0.02,
    }
    cfg = parse_rig_config(doc, tmp_path / "rig.yaml")
    cam = cfg.cameras["cam2"]
    assert cam.images == tmp_path / "rec" / "c2.mp4"
    assert (cam.every, cam.max_frames, cam.skip_blurred, cam.min_change) == (3, 40, True, 0.02)
    cam0 = cfg.cameras["cam0"]
    assert (cam0.every, cam0.max_frames, cam0.skip_blurred, cam0.min_change) == (
        1,
        None,
        False,
        None,
    )


@pytest.mark.parametrize(
    ("entry", "key", "says"),
    [
        ({"video": "v.mp4", "images": "imgs"}, "cameras.cam2", "give one of 'poses'"),
        ({"video": "v.mp4", "poses": "c.tum"}, "cameras.cam2", "give one of 'poses'"),
        ({"video": "v.mp4", "fps": 30}, "cameras.cam2.fps", "carry their own times"),
        (
            {"images": "imgs", "every": 2},
            "cameras.cam2",
            "'every', 'max_frames', 'skip_blurred', 'min_change' go with 'video'",
        ),
        ({"images": "imgs", "skip_blurred": True}, "cameras.cam2", "go with 'video' or 'bag'"),
        ({"video": "v.mp4", "min_change": 1.5}, "cameras.cam2.min_change", "less than 1"),
        ({"video": "v.mp4", "every": 0}, "cameras.cam2.every", "must be at least 1"),
        ({"bag": "r.bag"}, "cameras.cam2.topic", "missing (a bag needs its image topic)"),
        ({"images": "imgs", "topic": "/c"}, "cameras.cam2.topic", "goes with 'bag'"),
        ({"bag": "r.bag", "topic": "/c", "fps": 30}, "cameras.cam2.fps", "own times"),
        ({"bag": "r.bag", "video": "v.mp4", "topic": "/c"}, "cameras.cam2", "give one of"),
    ],
)
def test_a_bad_video_or_bag_entry_is_one_line_naming_its_key(
    tmp_path: Path, entry: dict[str, Any], key: str, says: str
) -> None:
    doc = copy.deepcopy(RIG)
    doc["cameras"]["cam2"] = entry
    _refused_naming(doc, tmp_path, key, says)


def _refused_naming(doc: dict[str, Any], tmp_path: Path, key: str, says: str) -> None:
    """``doc`` is refused in one line that starts with ``key`` and says ``says``."""
    with pytest.raises(InputError) as info:
        parse_rig_config(doc, tmp_path / "rig.yaml")
    assert info.value.message.startswith(f"key '{key}': "), info.value.message
    assert says in info.value.message


def test_a_camera_takes_a_bag_with_its_topic(tmp_path: Path) -> None:
    doc = copy.deepcopy(RIG)
    doc["cameras"]["cam2"] = {"bag": "rec/run.bag", "topic": "/cam2/image_raw", "every": 2}
    cam = parse_rig_config(doc, tmp_path / "rig.yaml").cameras["cam2"]
    assert cam.images == tmp_path / "rec" / "run.bag"
    assert (cam.topic, cam.every) == ("/cam2/image_raw", 2)


def test_a_bag_camera_may_use_structure_from_motion(tmp_path: Path) -> None:
    doc = copy.deepcopy(RIG)
    doc["cameras"]["cam2"] = {"bag": "r.bag", "topic": "/c", "front_end": "sfm", "scale": "unknown"}
    cfg = parse_rig_config(doc, tmp_path / "rig.yaml")
    assert cfg.cameras["cam2"].topic == "/c" and cfg.cameras["cam2"].front_end == "sfm"


@pytest.mark.parametrize(
    ("axis", "key", "says"),
    [
        ({"towards": "nobody"}, "joints.j12.axis.towards", "must name one of the rig's bodies"),
        ({"direction": [0, 0, 1]}, "joints.j12.axis", "give 'direction' with 'in'"),
        ({"direction": [0, 0, 1], "in": "cam0"}, "joints.j12.axis.in", "joint's bodies"),
        ({"direction": [0, 0, 0], "in": "cam1"}, "joints.j12.axis.direction", "not be zero"),
        ({"towards": "cam0", "in": "cam1"}, "joints.j12.axis", "not both"),
        ({"towards": "cam1"}, "joints.j12.axis.towards", "cam1 lies across the axis"),
    ],
)
def test_a_bad_axis_convention_is_one_line_naming_its_key(
    tmp_path: Path, axis: dict[str, Any], key: str, says: str
) -> None:
    doc = copy.deepcopy(RIG)
    doc["joints"]["j12"] = {"between": ["cam1", "cam2"], "type": "hinge", "axis": axis}
    _refused_naming(doc, tmp_path, key, says)


def test_a_ball_joint_has_no_axis_to_orient(tmp_path: Path) -> None:
    doc = copy.deepcopy(RIG)
    doc["joints"]["j12"] = {
        "between": ["cam1", "cam2"],
        "type": "ball",
        "axis": {"towards": "cam0"},
    }
    with pytest.raises(InputError, match="a ball joint has no axis"):
        parse_rig_config(doc, tmp_path / "rig.yaml")


@pytest.mark.parametrize(
    ("point", "key", "says"),
    [
        ({"nearest": [0, 0, 1]}, "joints.j12.point.in", "missing (required)"),
        ({"in": "cam2"}, "joints.j12.point.nearest", "missing (required)"),
        ({"nearest": [0, 0, 1], "in": "cam0"}, "joints.j12.point.in", "joint's bodies"),
        ({"nearest": [0, 1], "in": "cam2"}, "joints.j12.point.nearest", "three numbers"),
        ({"nearest": [0, 0, ".nan"], "in": "cam2"}, "joints.j12.point.nearest", "three numbers"),
        ({"nearest": [0, 0, 1], "in": "cam2", "at": 1}, "joints.j12.point.at", "unknown key"),
        ([0, 0, 1], "joints.j12.point", "must be a mapping"),
    ],
)
def test_a_bad_hinge_point_is_one_line_naming_its_key(
    tmp_path: Path, point: Any, key: str, says: str
) -> None:
    doc = copy.deepcopy(RIG)
    doc["joints"]["j12"] = {"between": ["cam1", "cam2"], "type": "hinge", "point": point}
    with pytest.raises(InputError) as info:
        parse_rig_config(doc, tmp_path / "rig.yaml")
    assert info.value.message.startswith(f"key '{key}': "), info.value.message
    assert says in info.value.message and "\n" not in info.value.message


@pytest.mark.parametrize(
    ("joint_type", "says"),
    [("ball", "a ball joint's point is its centre"), ("rigid", "a rigid joint has no point")],
)
def test_only_a_hinge_point_is_chosen(tmp_path: Path, joint_type: str, says: str) -> None:
    doc = copy.deepcopy(RIG)
    point = {"nearest": [0, 0, 1], "in": "cam2"}
    doc["joints"]["j12"] = {"between": ["cam1", "cam2"], "type": joint_type, "point": point}
    with pytest.raises(InputError) as info:
        parse_rig_config(doc, tmp_path / "rig.yaml")
    assert info.value.message.startswith("key 'joints.j12.point': " + says), info.value.message


def test_a_hinge_point_is_kept_with_its_body(tmp_path: Path) -> None:
    doc = copy.deepcopy(RIG)
    point = {"nearest": [0.1, -0.2, 1.5], "in": "cam2"}
    doc["joints"]["j12"] = {"between": ["cam1", "cam2"], "type": "hinge", "point": point}
    spec = parse_rig_config(doc, tmp_path / "rig.yaml").joints["j12"]
    assert spec.point_nearest is not None and spec.point_nearest[0] == "cam2"
    assert spec.point_nearest[1].tolist() == [0.1, -0.2, 1.5]
    assert spec.axis_direction is None and spec.axis_towards is None
