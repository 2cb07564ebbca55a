"""What a script sees (issue 12): ``--json`` on every command, and unwrapped piped output.

Every command is the installed ``acscal`` over real files, stdout piped. With ``--json``
stdout holds one JSON document (schema ``acscal/cli-result``) whose numbers are the
artifact's, whose ``written`` files exist, and nothing else; errors keep their exit code and
one-line message on stderr, with an error document on stdout.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from cli_runner import ACSCAL, acscal

from acs_cli.io.trajectory import read_trajectory, write_tum
from sample_data_gen import acs_sim
from sample_data_gen.writer import write_rig_recording

PHOTOS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "opencv_chessboard"


def result_of(res: subprocess.CompletedProcess[str], command: str) -> dict[str, Any]:
    """The document of a successful ``--json`` run: one line on stdout, common keys checked."""
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("\n") == 1 and res.stdout.endswith("\n"), res.stdout
    doc = json.loads(res.stdout)
    assert doc["schema"] == "acscal/cli-result" and doc["schema_version"] == 1
    assert doc["command"] == command
    assert doc["ok"] is True and doc["exit_code"] == 0
    assert isinstance(doc["warnings"], list)
    for path in doc["written"]:
        assert Path(path).exists(), path
    return doc


def load(path: str | Path) -> dict[str, Any]:
    return yaml.safe_load(Path(path).read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A fixed-joint and a general-motion recording of one rig, as TUM files."""
    rng = np.random.default_rng(12)
    rig = acs_sim.make_rig(rng)
    d = tmp_path_factory.mktemp("json")
    files: dict[str, Path] = {"dir": d}
    seqs = {
        "fixed": acs_sim.fixed_joint_sequence(rng, rig, 20),
        "general": acs_sim.general_sequence(rng, rig, 20),
    }
    for name, seq in seqs.items():
        for cam, T in (("a", seq.T_wa_a), ("b", seq.T_wb_b)):
            files[f"{name}_{cam}"] = d / f"{name}_{cam}.tum"
            write_tum(
                files[f"{name}_{cam}"], seq.timestamps, acs_sim.add_pose_noise(rng, T, 0.3, 0.005)
            )
    return files


@pytest.fixture(scope="module")
def calibrated(recording: dict[str, Path]) -> dict[str, Any]:
    """``joint``, ``relpose`` and ``trajectory`` run once with ``--json``."""
    d = recording["dir"]
    runs: dict[str, Any] = {}
    runs["joint"] = acscal(
        "joint", "--fixed-joint", "--poses-a", recording["fixed_a"], "--poses-b",
        recording["fixed_b"], "-o", d / "joint.yaml", "--json",
    )  # fmt: skip
    runs["relpose"] = acscal(
        "relpose", "--joint", d / "joint.yaml", "--poses-a", recording["general_a"],
        "--poses-b", recording["general_b"], "-o", d / "relpose.yaml", "--json",
    )  # fmt: skip
    runs["trajectory"] = acscal(
        "trajectory", "--relpose", d / "relpose.yaml", "--poses-a", recording["general_a"],
        "--poses-b", recording["general_b"], "-o", d / "traj", "--json",
    )  # fmt: skip
    return runs


def test_joint_json_holds_the_artifact_numbers(
    recording: dict[str, Path], calibrated: dict[str, Any]
) -> None:
    res = calibrated["joint"]
    doc = result_of(res, "joint")
    art = load(recording["dir"] / "joint.yaml")
    assert doc["written"] == [str(recording["dir"] / "joint.yaml")]
    assert doc["warnings"] == art["warnings"]
    got = doc["result"]
    assert got["schema"] == "acscal/joint" and got["units"]["length"] == "m"
    assert got["scenario"] == "fixed_joint"
    for key in ("position_in_a", "position_in_a_std", "position_in_b", "position_in_b_std"):
        assert got["joint"][key] == pytest.approx(art["joint"][key], rel=1e-12), key
    assert got["quality"]["residual_rms"] == pytest.approx(art["quality"]["residual_rms"])
    # the human table went to stderr, not into the document
    assert "position_in_a" in res.stderr and "wrote" in res.stderr


def test_relpose_json_holds_pose_scale_and_std(
    recording: dict[str, Path], calibrated: dict[str, Any]
) -> None:
    doc = result_of(calibrated["relpose"], "relpose")
    art = load(recording["dir"] / "relpose.yaml")
    rel, got = art["relative_pose"], doc["result"]["relative_pose"]
    np.testing.assert_allclose(got["T_b_a"], rel["T_b_a"], rtol=1e-12)
    for key in ("rpy_deg", "rpy_deg_std", "translation_b_in_a", "translation_b_in_a_std"):
        assert got[key] == pytest.approx(rel[key], rel=1e-12), key
    assert doc["result"]["joint"]["position_in_b"] == pytest.approx(
        art["joint"]["position_in_b"], rel=1e-12
    )
    assert doc["result"]["quality"]["residual_rms"] == pytest.approx(art["quality"]["residual_rms"])
    assert doc["written"] == [str(recording["dir"] / "relpose.yaml")]


def test_trajectory_json_lists_every_file_written(
    recording: dict[str, Path], calibrated: dict[str, Any]
) -> None:
    doc = result_of(calibrated["trajectory"], "trajectory")
    traj = recording["dir"] / "traj"
    assert sorted(Path(p).name for p in doc["written"]) == [
        "angles.csv", "cam_a.tum", "cam_b.tum", "joint.tum", "trajectory.yaml"
    ]  # fmt: skip
    art = load(traj / "trajectory.yaml")
    assert doc["result"]["consistency"]["rms"] == pytest.approx(art["consistency"]["rms"])
    assert len(read_trajectory(traj / "cam_b.tum")) == len(art["consistency"]["frames"]["distance"])


def test_export_json_or_its_error_document(
    recording: dict[str, Path], calibrated: dict[str, Any], tmp_path: Path
) -> None:
    """Export's own rules belong to its tests; here: the document matches the exit code."""
    assert calibrated["relpose"].returncode == 0
    out = tmp_path / "relpose_cv.yaml"
    res = acscal(
        "export", recording["dir"] / "relpose.yaml", "--format", "opencv", "-o", out, "--json"
    )
    doc = json.loads(res.stdout)
    assert doc["command"] == "export" and doc["exit_code"] == res.returncode
    if res.returncode == 0:
        assert doc["ok"] is True and str(out) in doc["written"] and out.is_file()
    else:
        assert res.returncode == 2 and doc["ok"] is False
        assert res.stderr.strip() == f"acscal: error: {doc['error']['message']}"


def test_errors_keep_their_exit_code_and_line_with_a_json_document(
    recording: dict[str, Path], tmp_path: Path
) -> None:
    bad = tmp_path / "bad.tum"
    bad.write_text("0 0 0 0 nan 0 0 1\n", encoding="utf-8")
    translating = tmp_path / "translating.tum"
    translating.write_text(
        "".join(f"{0.1 * i:.1f} {0.05 * i:.3f} 0 0 0 0 0 1\n" for i in range(20)), encoding="utf-8"
    )
    for poses, code, kind in ((bad, 2, "InputError"), (translating, 3, "DegenerateMotionError")):
        out = tmp_path / f"joint_{code}.yaml"
        res = acscal("joint", "--json", "--fixed-joint", "--poses-a", poses, "-o", out)
        assert res.returncode == code, res.stderr
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("acscal: error: "), res.stderr
        doc = json.loads(res.stdout)
        assert doc["ok"] is False and doc["exit_code"] == code and doc["written"] == []
        assert doc["error"]["type"] == kind
        assert lines[0] == f"acscal: error: {doc['error']['message']}"
        assert not out.exists()
    # a usage error after --json was read: exit 2, the same two outputs
    res = acscal("relpose", "--json", "--poses-a", bad, "-o", tmp_path / "r.yaml")
    assert res.returncode == 2
    assert json.loads(res.stdout)["error"]["type"] == "UsageError"


def test_run_and_report_json(tmp_path: Path) -> None:
    """A rig run (the version-2 config) lists every stage; ``report`` its figures."""
    write_rig_recording(tmp_path, seed=5, frames=40)
    doc = result_of(acscal("run", tmp_path / "config.yaml", "--json"), "run")
    stages = {s["stage"]: s for s in doc["result"]["stages"]}
    assert stages["rig"]["status"] == "ran" and doc["result"]["ran"] == ["rig"]
    assert stages["report"]["status"] == "written"
    rig_yaml = tmp_path / "out" / "rig.yaml"
    assert (
        str(rig_yaml) in doc["written"] and str(tmp_path / "out" / "report.html") in doc["written"]
    )
    assert set(stages["rig"]["outputs"]) <= set(doc["written"])
    assert load(rig_yaml)["schema"] == "acscal/rig"
    # a second run skips the rig: nothing of it is written again
    again = result_of(acscal("run", tmp_path / "config.yaml", "--json"), "run")
    assert again["result"]["skipped"] == ["rig"]
    assert str(rig_yaml) not in again["written"]

    html = tmp_path / "again" / "report.html"
    doc = result_of(acscal("report", tmp_path / "out", "-o", html, "--json"), "report")
    assert doc["result"]["output"] == str(html) and doc["written"][0] == str(html)
    pngs = [p for p in doc["written"] if p.endswith(".png")]
    assert pngs and all(Path(p).parent == Path(doc["result"]["figures_dir"]) for p in pngs)


def test_simulate_json(tmp_path: Path) -> None:
    out = tmp_path / "study"
    args = ("--trials", "1", "--levels", "2", "--frames", "5")
    doc = result_of(acscal("simulate", "-o", out, *args, "--json"), "simulate")
    rows = (out / "trials.csv").read_text(encoding="utf-8").splitlines()
    assert doc["result"]["n_rows"] == len(rows) - 1
    assert str(out / "trials.csv") in doc["written"]
    assert sum(p.endswith(".png") for p in doc["written"]) == len(list(out.glob("fig*.png")))


@pytest.mark.skipif(not PHOTOS.is_dir(), reason=f"OpenCV sample photographs not at {PHOTOS}")
def test_intrinsics_and_poses_json_on_photographs(tmp_path: Path) -> None:
    images = tmp_path / "left"
    images.mkdir()
    for p in sorted(PHOTOS.glob("left*.jpg")):
        shutil.copy(p, images / p.name)
    intr = tmp_path / "intrinsics.yaml"
    doc = result_of(
        acscal("intrinsics", images, "--board", "9x6", "--square", "0.025", "-o", intr, "--json"),
        "intrinsics",
    )
    art = load(intr)
    got = doc["result"]
    np.testing.assert_allclose(got["camera_matrix"], art["camera_matrix"], rtol=1e-12)
    assert got["distortion"] == pytest.approx(art["distortion"], rel=1e-12)
    assert got["rms_px"] == pytest.approx(art["rms_px"]) and got["std"]["fx"] > 0
    assert doc["written"] == [str(intr)]

    poses, tum = tmp_path / "poses.npz", tmp_path / "poses.txt"
    doc = result_of(
        acscal("poses", images, "--intrinsics", intr, "-o", poses, "--tum", tum, "--json"), "poses"
    )
    assert doc["written"] == [str(poses), str(tum)]
    traj = read_trajectory(poses)
    assert doc["result"]["poses"] == len(traj)
    assert list(doc["result"]["reprojection_rms_px"]["per_image"]) == list(traj.names)
    assert doc["result"]["time_unit"] == traj.time_unit
    assert 0 < doc["result"]["reprojection_rms_px"]["median"] < 1.0


def test_a_path_rich_would_read_as_markup_is_printed_as_it_is(
    recording: dict[str, Path], tmp_path: Path
) -> None:
    """Brackets and colons in a path are the path's: rich's markup took ``[v2]`` for a style
    (and printed the path without it) and a closing tag such as ``[/v2]`` for an error."""
    out = tmp_path / "run[v2]" / "[/v2]" / "a:smile:b" / "joint.yaml"
    res = acscal(
        "joint", "--fixed-joint", "--poses-a", recording["fixed_a"],
        "--poses-b", recording["fixed_b"], "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert out.is_file()
    assert [ln for ln in res.stdout.splitlines() if "wrote" in ln] == [f"wrote {out}"]


def test_a_long_path_is_one_line_when_piped(recording: dict[str, Path], tmp_path: Path) -> None:
    """``acscal ... | grep wrote`` finds the whole path, whatever the terminal's width."""
    out = tmp_path / ("a_rather_long_folder_name_" * 8) / "joint.yaml"
    res = subprocess.run(
        [str(ACSCAL), "joint", "--fixed-joint", "--poses-a", str(recording["fixed_a"]),
         "--poses-b", str(recording["fixed_b"]), "-o", str(out)],
        capture_output=True, text=True, env=dict(os.environ, COLUMNS="80", NO_COLOR="1"),
        timeout=300,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert len(str(out)) > 200
    assert [ln for ln in res.stdout.splitlines() if "wrote" in ln] == [f"wrote {out}"]
