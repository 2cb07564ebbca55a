"""``--target``: Kalibr's and OpenCV's target YAML files and the short forms, with errors
that name the key."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from acs_cli.core.targets import AprilGrid, Charuco, Checkerboard
from acs_cli.errors import InputError
from acs_cli.io.target import parse_target, parse_target_short, target_from_mapping
from acs_cli.stages.rig import parse_rig_config
from acs_cli.stages.run import parse_run_config

KALIBR_APRILGRID = """\
target_type: 'aprilgrid' #gridtype
tagCols: 6               #number of apriltags
tagRows: 6               #number of apriltags
tagSize: 0.088           #size of apriltag, edge to edge [m]
tagSpacing: 0.3          #ratio of space between tags to tagSize
codeOffset: 0            #code offset for the first tag in the aprilboard
"""
CHARUCO = """\
target_type: charuco
squaresX: 11
squaresY: 8
squareLength: 0.03
markerLength: 0.022
dictionary: DICT_5X5_100
"""
KALIBR_CHECKERBOARD = """\
target_type: 'checkerboard' #gridtype
targetCols: 9               #number of internal chessboard corners
targetRows: 6               #number of internal chessboard corners
rowSpacingMeters: 0.025     #size of one chessboard square [m]
colSpacingMeters: 0.025     #size of one chessboard square [m]
"""


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        (KALIBR_APRILGRID, AprilGrid(6, 6, 0.088, 0.3)),
        (CHARUCO, Charuco(11, 8, 0.03, 0.022, "DICT_5X5_100")),
        (KALIBR_CHECKERBOARD, Checkerboard(9, 6, 0.025)),
    ],
    ids=["kalibr-aprilgrid", "opencv-charuco", "kalibr-checkerboard"],
)
def test_target_yaml_files(tmp_path: Path, text: str, expected: object) -> None:
    f = tmp_path / "target.yaml"
    f.write_text(text)
    assert parse_target(str(f)) == expected


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("aprilgrid:6x6:0.088:0.3", AprilGrid(6, 6, 0.088, 0.3)),
        ("aprilgrid:7X5:0.05:0.25", AprilGrid(7, 5, 0.05, 0.25)),
        ("charuco:11x8:0.03:0.022:DICT_5X5_100", Charuco(11, 8, 0.03, 0.022, "DICT_5X5_100")),
        ("checkerboard:9x6:0.025", Checkerboard(9, 6, 0.025)),
    ],
)
def test_short_forms(text: str, expected: object) -> None:
    target = parse_target(text)
    assert target == expected
    assert parse_target_short(target.short()) == target  # short() is its inverse


@pytest.mark.parametrize(
    ("doc", "key"),
    [
        ({"target_type": "circles", "tagCols": 6}, "target_type"),
        ({"target_type": 3}, "target_type"),
        ({"tagCols": 6}, "target_type"),
        ({"target_type": "aprilgrid", "tagCols": "six", "tagRows": 6, "tagSize": 0.1,
          "tagSpacing": 0.3}, "tagCols"),
        ({"target_type": "aprilgrid", "tagCols": 6, "tagRows": 6, "tagSize": "big",
          "tagSpacing": 0.3}, "tagSize"),
        ({"target_type": "aprilgrid", "tagCols": 6, "tagRows": 6, "tagSize": 0.1}, "tagSpacing"),
        ({"target_type": "aprilgrid", "tagCols": 6, "tagRows": 6, "tagSize": 0.1,
          "tagSpacing": 0.3, "codeOffset": 36}, "codeOffset"),
        ({"target_type": "charuco", "squaresX": 11, "squaresY": 8, "squareLength": 0.03,
          "markerLength": 0.022, "dictionary": "DICT_5X5"}, "dictionary"),
        ({"target_type": "charuco", "squaresX": 11, "squaresY": 8, "squareLength": 0.03,
          "markerLength": 0.022, "dictionary": 5}, "dictionary"),
        ({"target_type": "charuco", "squaresX": 11, "squaresY": 8, "squareLength": 0.03,
          "markerLength": 0.04, "dictionary": "DICT_5X5_100"}, "markerLength"),
        ({"target_type": "charuco", "squaresX": 11.5, "squaresY": 8, "squareLength": 0.03,
          "markerLength": 0.022, "dictionary": "DICT_5X5_100"}, "squaresX"),
        ({"target_type": "checkerboard", "targetCols": 9, "targetRows": 6,
          "rowSpacingMeters": 0.025, "colSpacingMeters": 0.03}, "colSpacingMeters"),
        ({"target_type": "checkerboard", "targetCols": 9, "targetRows": [6],
          "rowSpacingMeters": 0.025, "colSpacingMeters": 0.025}, "targetRows"),
    ],
)  # fmt: skip
def test_bad_yaml_names_the_key(tmp_path: Path, doc: dict[str, object], key: str) -> None:
    with pytest.raises(InputError, match=f"'{key}'") as exc:
        target_from_mapping(doc, tmp_path / "t.yaml")
    assert exc.value.exit_code == 2
    assert exc.value.path == str(tmp_path / "t.yaml")


def test_nested_key_is_named() -> None:
    with pytest.raises(InputError, match=r"'target\.tagSize'"):
        target_from_mapping(
            {"target_type": "aprilgrid", "tagCols": 6, "tagRows": 6, "tagSize": -1,
             "tagSpacing": 0.3}, None, "target",
        )  # fmt: skip


def test_a_file_that_is_not_a_mapping(tmp_path: Path) -> None:
    f = tmp_path / "list.yaml"
    f.write_text("- 1\n- 2\n")
    with pytest.raises(InputError, match="target"):
        parse_target(str(f))
    with pytest.raises(InputError, match="no such file"):
        parse_target(str(tmp_path / "missing.yaml"))


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("circles:3x3:0.1", "unknown target type 'circles'"),
        ("aprilgrid:6x6:0.088", "aprilgrid:COLSxROWS:tagSize:tagSpacing"),
        ("aprilgrid:6by6:0.088:0.3", "COLSxROWS must look like 6x6"),
        ("aprilgrid:6x6:-0.088:0.3", "tagSize must be a positive number"),
        ("aprilgrid:6x6:0.088:nan", "tagSpacing must be a positive number"),
        ("charuco:11x8:0.03:0.022:DICT_NOPE", "dictionary"),
        ("charuco:11x8:0.03:0.04:DICT_5X5_100", "marker length"),
        ("checkerboard:1x6:0.025", "2x2"),
    ],
)
def test_bad_short_forms(text: str, words: str) -> None:
    with pytest.raises(InputError, match=words):
        parse_target(text)


RUN = """\
schema: acscal/run-config
schema_version: 1
output: out
cameras:
  a: {images: imgs}
joint: {scenario: fixed_joint}
"""
RIG = """\
output: out
cameras:
  c0: {images: imgs0}
  c1: {images: imgs1}
joints:
  j: {between: [c0, c1], type: ball}
"""


@pytest.mark.parametrize(
    ("line", "expected"),
    [
        ("target: aprilgrid:6x6:0.088:0.3", AprilGrid(6, 6, 0.088, 0.3)),
        (
            "target: {target_type: charuco, squaresX: 5, squaresY: 7, squareLength: 0.04, "
            "markerLength: 0.03, dictionary: DICT_4X4_50}",
            Charuco(5, 7, 0.04, 0.03, "DICT_4X4_50"),
        ),
        ("target: april.yaml", AprilGrid(6, 6, 0.088, 0.3)),  # beside the config
    ],
)
def test_run_configs_name_a_target(tmp_path: Path, line: str, expected: object) -> None:
    (tmp_path / "april.yaml").write_text(KALIBR_APRILGRID)
    run = parse_run_config(yaml.safe_load(RUN + line), tmp_path / "run.yaml")
    assert run.target == expected
    rig = parse_rig_config(yaml.safe_load(RIG + line), tmp_path / "rig.yaml")
    assert rig.target == expected and rig.board is None


def test_run_config_target_errors_name_the_key(tmp_path: Path) -> None:
    cfg = tmp_path / "run.yaml"
    both = RUN + "board: {cols: 9, rows: 6, square: 0.025}\ntarget: aprilgrid:6x6:0.088:0.3"
    with pytest.raises(InputError, match="'target'"):
        parse_run_config(yaml.safe_load(both), cfg)
    with pytest.raises(InputError, match="'board'"):
        parse_run_config(yaml.safe_load(RUN), cfg)
    bad = RUN + "target: {target_type: aprilgrid, tagCols: 6, tagRows: 6, tagSize: x}"
    with pytest.raises(InputError, match=r"'target\.tagSize'"):
        parse_run_config(yaml.safe_load(bad), cfg)
    # a checkerboard named as a target is the board
    run = parse_run_config(yaml.safe_load(RUN + "target: checkerboard:7x5:0.03"), cfg)
    assert (run.cols, run.rows, run.square, run.target) == (7, 5, 0.03, None)
