"""Run configs (``acscal run``): every key checked, paths resolved against the config."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

from acs_cli.errors import InputError
from acs_cli.stages.run import load_run_config, parse_run_config

CONFIGS = Path(__file__).resolve().parents[2] / "configs"

BASE: dict[str, Any] = {
    "schema": "acscal/run-config",
    "schema_version": 1,
    "output": "out/",
    "board": {"cols": 9, "rows": 6, "square": 0.025},
    "cameras": {
        "a": {"images": "data/fixed_joint/cam_a", "model": "pinhole"},
        "b": {"images": "data/fixed_joint/cam_b"},
    },
    "joint": {"scenario": "fixed_joint", "method": "refined"},
    "relpose": {
        "images": {"a": "data/general/cam_a", "b": "data/general/cam_b"},
        "method": "refined",
        "unknown_scale": False,
        "self_calibrate": False,
        "reference": 0,
    },
}


def _write(tmp_path: Path, doc: Any) -> Path:
    path = tmp_path / "cfg" / "run.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(doc), encoding="utf-8")
    return path


def _with(change: dict[str, Any]) -> dict[str, Any]:
    """BASE with dotted keys set (value ``...`` deletes the key)."""
    doc = copy.deepcopy(BASE)
    for dotted, value in change.items():
        *parents, last = dotted.split(".")
        node = doc
        for p in parents:
            node = node[p]
        if value is ...:
            del node[last]
        else:
            node[last] = value
    return doc


def test_valid_config_resolves_paths_against_its_folder(tmp_path: Path) -> None:
    path = _write(tmp_path, BASE)
    cfg = load_run_config(path)
    base = path.parent
    assert cfg.output == base / "out"
    assert cfg.cameras["a"].images == base / "data" / "fixed_joint" / "cam_a"
    assert cfg.cameras["b"].model == "pinhole"
    assert cfg.relpose is not None
    assert cfg.relpose.images["b"] == base / "data" / "general" / "cam_b"
    assert (cfg.cols, cfg.rows, cfg.square) == (9, 6, 0.025)
    assert cfg.intrinsics_images == "all"
    assert cfg.joint is not None and cfg.joint.scenario == "fixed_joint"


def test_absolute_paths_and_intrinsics_from_folder(tmp_path: Path) -> None:
    other = tmp_path / "previous_run"
    doc = _with({"output": str(tmp_path / "abs_out"), "intrinsics_from": "../previous_run"})
    cfg = load_run_config(_write(tmp_path, doc))
    assert cfg.output == tmp_path / "abs_out"
    assert cfg.intrinsics_from == {
        "a": other / "cam_a" / "intrinsics.yaml",
        "b": other / "cam_b" / "intrinsics.yaml",
    }


@pytest.mark.parametrize(
    ("change", "key"),
    [
        ({"colour": "red"}, "colour"),
        ({"schema": "acscal/joint"}, "schema"),
        ({"schema_version": 99}, "schema_version"),
        ({"schema_version": ...}, "schema_version"),
        ({"output": ...}, "output"),
        ({"output": 3}, "output"),
        ({"board": ...}, "board"),
        ({"board.cols": "nine"}, "board.cols"),
        ({"board.rows": 1}, "board.rows"),
        ({"board.rows": True}, "board.rows"),
        ({"board.square": -0.1}, "board.square"),
        ({"board.squares": 0.1}, "board.squares"),
        ({"cameras.a": ...}, "cameras.a"),
        ({"cameras.c": {"images": "x"}}, "cameras.c"),
        ({"cameras.a.model": "kannala"}, "cameras.a.model"),
        ({"cameras.a.lens": "x"}, "cameras.a.lens"),
        ({"cameras.b.images": ...}, "cameras.b.images"),
        ({"intrinsics": {"from": "everything"}}, "intrinsics.from"),
        ({"intrinsics_from": 5}, "intrinsics_from"),
        ({"joint.scenario": "hinge"}, "joint.scenario"),
        ({"joint.scenario": ...}, "joint.scenario"),
        ({"joint.method": "best"}, "joint.method"),
        ({"joint": ...}, "joint"),
        ({"relpose.images": ...}, "relpose.images"),
        ({"relpose.images.b": ...}, "relpose.images.b"),
        ({"relpose.unknown_scale": "yes"}, "relpose.unknown_scale"),
        ({"relpose.self_calibrate": True}, "relpose.self_calibrate"),
        ({"relpose.reference": -1}, "relpose.reference"),
        ({"relpose.refrence": 0}, "relpose.refrence"),
        ({"workers": 0}, "workers"),
    ],
)
def test_bad_key_is_named(tmp_path: Path, change: dict[str, Any], key: str) -> None:
    path = _write(tmp_path, _with(change))
    with pytest.raises(InputError) as info:
        load_run_config(path)
    assert f"'{key}'" in info.value.message
    line = info.value.one_line()
    assert line.startswith(str(path)) and "\n" not in line


def test_not_a_mapping_and_bad_yaml(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="must be a mapping"):
        parse_run_config(["a"], tmp_path / "c.yaml")
    path = tmp_path / "bad.yaml"
    path.write_text("schema: [unclosed\n", encoding="utf-8")
    with pytest.raises(InputError, match="not valid YAML"):
        load_run_config(path)
    with pytest.raises(InputError, match="no such file"):
        load_run_config(tmp_path / "missing.yaml")


def test_self_calibration_needs_no_joint_images(tmp_path: Path) -> None:
    doc = _with(
        {
            "joint": ...,
            "cameras.a.images": ...,
            "cameras.b.images": ...,
            "relpose.self_calibrate": True,
        }
    )
    cfg = load_run_config(_write(tmp_path, doc))
    assert cfg.joint is None and cfg.relpose is not None and cfg.relpose.self_calibrate
    doc["intrinsics"] = {"from": "joint"}
    with pytest.raises(InputError, match=r"'intrinsics\.from'"):
        load_run_config(_write(tmp_path, doc))


@pytest.mark.parametrize("name", ["overlap", "fixed_joint", "general_selfcal"])
def test_example_configs_are_valid(name: str) -> None:
    cfg = load_run_config(CONFIGS / f"{name}.yaml")
    assert (cfg.cols, cfg.rows, cfg.square) == (9, 6, 0.025)  # render_sample_set's board
    images = [c.images for c in cfg.cameras.values() if c.images is not None]
    if cfg.relpose is not None:
        images += list(cfg.relpose.images.values())
    root = CONFIGS.parent / "demo_out" / "images"
    assert images and all(p.parent.parent == root for p in images)


def test_cameras_take_fps_or_a_timestamps_file(tmp_path: Path) -> None:
    doc = _with({"cameras.a.fps": 30, "cameras.b.timestamps": "data/b_times.csv"})
    cfg = load_run_config(_write(tmp_path, doc))
    assert cfg.cameras["a"].fps == 30.0 and cfg.cameras["a"].timestamps is None
    assert cfg.cameras["b"].timestamps == tmp_path / "cfg" / "data" / "b_times.csv"
    both = _with({"cameras.a.fps": 30, "cameras.a.timestamps": "t.csv"})
    with pytest.raises(InputError, match=r"cameras\.a.*not both"):
        load_run_config(_write(tmp_path, both))
    with pytest.raises(InputError, match=r"cameras\.a\.fps"):
        load_run_config(_write(tmp_path, _with({"cameras.a.fps": -1})))


def test_rig_cameras_take_times_only_with_images(tmp_path: Path) -> None:
    from acs_cli.stages.rig import parse_rig_config

    doc = {
        "schema": "acscal/run-config",
        "schema_version": 2,
        "output": "out/",
        "board": {"cols": 9, "rows": 6, "square": 0.025},
        "cameras": {
            "a": {"images": "imgs/a", "fps": 25},
            "b": {"poses": "b.tum", "fps": 25},
        },
        "joints": {"j": {"between": ["a", "b"], "type": "ball"}},
    }
    with pytest.raises(InputError, match=r"cameras\.b.*go with .images."):
        parse_rig_config(doc, tmp_path / "rig.yaml")
    doc["cameras"]["b"] = {"images": "imgs/b", "timestamps": "b.csv"}
    cfg = parse_rig_config(doc, tmp_path / "rig.yaml")
    assert cfg.cameras["a"].fps == 25.0 and cfg.cameras["b"].timestamps == tmp_path / "b.csv"


def test_an_absurd_square_is_refused_naming_the_key(tmp_path: Path) -> None:
    text = (
        "schema_version: 2\noutput: out/\n"
        "board: {cols: 9, rows: 6, square: 1000000000000000000000000000000}\n"
        "cameras:\n  a: {images: imgs}\n  b: {poses: b.tum}\n"
        "joints:\n  j: {between: [a, b], type: ball}\n"
    )
    (tmp_path / "c.yaml").write_text(text)
    with pytest.raises(InputError, match=r"board\.square"):
        load_run_config(tmp_path / "c.yaml")
