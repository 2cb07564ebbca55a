"""Faults found by probing (issue 13): tracebacks, outputs replaced or cut, inputs read
without end. Each now exits 2 with one line naming the file or the option (or works)."""

from __future__ import annotations

import gzip
import io
import json
import math
import os
import shutil
import signal
import stat
import subprocess
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.io.artifacts import make_header, write_yaml_artifact
from acs_cli.io.trajectory import write_tum
from acs_cli.stages.joint import JointConfig, run_joint
from acs_cli.stages.relpose import RelposeConfig, run_relpose
from sample_data_gen import acs_sim

try:
    import resource
except ImportError:  # pragma: no cover - not POSIX
    resource = None  # type: ignore[assignment]


def test_a_board_too_large_for_opencv_is_refused(tmp_path: Path) -> None:
    (tmp_path / "imgs").mkdir()
    (tmp_path / "imgs" / "a.png").write_bytes(b"")
    res = acscal("intrinsics", tmp_path / "imgs", "--board", "99999999999999999999x6",
                 "--square", "0.025", "-o", tmp_path / "i.yaml")  # fmt: skip
    assert res.returncode == 2 and "at most 1000 inner corners" in res.stderr
    assert "Traceback" not in res.stderr


def test_a_run_config_board_too_large_is_named(tmp_path: Path) -> None:
    cfg = tmp_path / "run.yaml"
    cfg.write_text(
        yaml.safe_dump(
            {
                "schema": "acscal/run-config",
                "schema_version": 1,
                "output": "out/",
                "board": {"cols": 10**20, "rows": 6, "square": 0.025},
                "cameras": {"a": {"images": "imgs"}},
                "joint": {"scenario": "fixed_joint"},
            }
        )
    )
    res = acscal("run", cfg)
    assert res.returncode == 2 and "board.cols" in res.stderr, res.stderr
    assert "Traceback" not in res.stderr


def test_simulation_noise_beyond_reason_is_refused(tmp_path: Path) -> None:
    res = acscal("simulate", "--max-trans", "1e300", "-o", tmp_path / "sim")
    assert res.returncode == 2 and "--max-trans" in res.stderr
    assert "Traceback" not in res.stderr


# --------------------------------------------------------------------------------------
# Outputs: devices, FIFOs and symlinks; full disks and file-size limits


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with trajectories (fixed joint, general motion), joint.yaml, relpose.yaml
    and cam_<x>/intrinsics.yaml, made in-process (the commands under test run end to end)."""
    d = tmp_path_factory.mktemp("probed")
    rng = np.random.default_rng(11)
    rig = acs_sim.make_rig(rng)
    seqs = {
        "fixed": acs_sim.fixed_joint_sequence(rng, rig, 20),
        "general": acs_sim.general_sequence(rng, rig, 20),
    }
    for name, seq in seqs.items():
        for cam, T in (("a", seq.T_wa_a), ("b", seq.T_wb_b)):
            write_tum(
                d / f"{name}_{cam}.tum", seq.timestamps, acs_sim.add_pose_noise(rng, T, 0.1, 0.002)
            )
    run_joint(d / "fixed_a.tum", d / "fixed_b.tum", d / "joint.yaml", JointConfig())
    run_relpose(d / "general_a.tum", d / "general_b.tum", d / "joint.yaml", d / "relpose.yaml",
                RelposeConfig())  # fmt: skip
    for cam, fx in (("a", 500.0), ("b", 600.0)):
        K = [[fx, 0.0, 376.5], [0.0, fx + 1.0, 240.25], [0.0, 0.0, 1.0]]
        body = {"model": "pinhole", "image_size": [752, 480], "camera_matrix": K,
                "distortion": [-0.2, 0.03, 2e-4, -1e-4, 0.0]}  # fmt: skip
        header = make_header("intrinsics", {}, "test", {}, {})
        write_yaml_artifact(d / f"cam_{cam}" / "intrinsics.yaml", header, body)
    return d


def _export(pair: Path, output: Path, fmt: str = "opencv", *extra: str, **kw: Any) -> Any:
    return acscal("export", pair / "relpose.yaml", "--format", fmt, "-o", output, *extra, **kw)


def _no_traceback(res: subprocess.CompletedProcess[str]) -> None:
    assert "Traceback" not in res.stderr, res.stderr


def test_an_output_symlink_is_written_through_to_its_target(pair: Path, tmp_path: Path) -> None:
    target = tmp_path / "real" / "relpose_cv.yaml"
    target.parent.mkdir()
    target.write_text("old\n")
    link = tmp_path / "link.yaml"
    link.symlink_to(target)
    res = _export(pair, link)
    assert res.returncode == 0, res.stderr
    assert link.is_symlink() and os.readlink(link) == str(target)
    fs = cv2.FileStorage(str(target), cv2.FILE_STORAGE_READ)
    assert fs.getNode("R").mat().shape == (3, 3)
    fs.release()
    assert sorted(p.name for p in target.parent.iterdir()) == ["relpose_cv.yaml"]


def test_an_output_that_is_a_fifo_is_refused_and_kept(pair: Path, tmp_path: Path) -> None:
    # a FIFO stands for every node that is not a regular file (/dev/null, a socket): never
    # replaced by a plain file
    fifo = tmp_path / "out.yaml"
    os.mkfifo(fifo)
    res = _export(pair, fifo, "opencv", "--json")
    assert res.returncode == 2 and "not a regular file" in res.stderr and "out.yaml" in res.stderr
    _no_traceback(res)
    doc = json.loads(res.stdout)
    assert doc["ok"] is False and doc["exit_code"] == 2
    assert "not a regular file" in doc["error"]["message"]
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    res = acscal("joint", "--fixed-joint", "--poses-a", pair / "fixed_a.tum",
                 "--poses-b", pair / "fixed_b.tum", "-o", fifo)  # fmt: skip
    assert res.returncode == 2 and "not a regular file" in res.stderr
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_a_symlink_loop_as_output_or_input_exits_2(pair: Path, tmp_path: Path) -> None:
    loop = tmp_path / "loop1"
    loop.symlink_to(tmp_path / "loop2")
    (tmp_path / "loop2").symlink_to(loop)
    res = _export(pair, loop)
    assert res.returncode == 2 and "symlink loop" in res.stderr, res.stderr
    _no_traceback(res)
    res = acscal("joint", "--fixed-joint", "--poses-a", loop, "--poses-b", pair / "fixed_b.tum",
                 "-o", tmp_path / "j.yaml")  # fmt: skip
    assert res.returncode == 2 and "symlink loop" in res.stderr, res.stderr
    _no_traceback(res)
    res = acscal("export", loop, "-o", tmp_path / "x.yaml")
    assert res.returncode == 2 and "loop1" in res.stderr
    _no_traceback(res)


def _file_size_limit(limit: int) -> Callable[[], None]:
    def limit_writes() -> None:  # in the child, before exec: a write beyond gets EFBIG
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    return limit_writes


@pytest.mark.skipif(resource is None, reason="needs POSIX resource limits")
@pytest.mark.parametrize("fmt", ["opencv", "kalibr", "joint", "tum"])
def test_a_write_cut_by_a_file_size_limit_fails_and_keeps_the_old_file(
    pair: Path, tmp_path: Path, fmt: str
) -> None:
    out = tmp_path / ("out.tum" if fmt == "tum" else "out.yaml")
    out.write_text("old\n")
    limit = _file_size_limit(600)  # each output is larger
    if fmt == "joint":
        res = acscal("joint", "--fixed-joint", "--poses-a", pair / "fixed_a.tum",
                     "--poses-b", pair / "fixed_b.tum", "-o", out, preexec_fn=limit)  # fmt: skip
    elif fmt == "tum":
        res = acscal("trajectory", "--relpose", pair / "relpose.yaml",
                     "--poses-a", pair / "general_a.tum", "--poses-b", pair / "general_b.tum",
                     "-o", tmp_path / "traj", preexec_fn=limit)  # fmt: skip
        out = tmp_path / "traj" / "cam_a.tum"
    else:
        res = _export(pair, out, fmt, preexec_fn=limit)
    assert res.returncode == 2, (res.stdout, res.stderr)
    assert "cannot write (File too large)" in res.stderr
    assert "wrote" not in res.stdout
    _no_traceback(res)
    if fmt != "tum":
        assert out.read_text() == "old\n"
    assert not [p for p in out.parent.iterdir() if ".tmp" in p.name]


def test_opencv_export_to_gz_is_gzip_and_reads_back(pair: Path, tmp_path: Path) -> None:
    for name in ("relpose.xml.gz", "relpose.yaml.gz"):
        out = tmp_path / name
        res = _export(pair, out)
        assert res.returncode == 0, res.stderr
        assert out.read_bytes()[:2] == b"\x1f\x8b"  # gzip, as cv2.FileStorage writes it
        with gzip.open(out, "rt") as fh:
            head = fh.read(40)
        assert head.startswith("<?xml" if ".xml" in name else "%YAML")
        fs = cv2.FileStorage(str(out), cv2.FILE_STORAGE_READ)
        assert fs.getNode("T_b_a").mat().shape == (4, 4)
        fs.release()


# --------------------------------------------------------------------------------------
# `acscal report -o` onto a run's own files


def test_report_refuses_to_overwrite_a_file_that_is_not_html(pair: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(pair, run)
    (run / ".acscal-run.yaml").write_text("schema: acscal/run-state\n")
    (run / "cam_a" / "poses.npz").write_bytes(b"PK\x03\x04 not really")
    for victim in (run / ".acscal-run.yaml", run / "cam_a" / "poses.npz", run / "general_a.tum",
                   run / "relpose.yaml"):  # fmt: skip
        before = victim.read_bytes()
        res = acscal("report", run, "-o", victim)
        assert res.returncode == 2, (victim, res.stderr)
        assert victim.name in res.stderr
        _no_traceback(res)
        assert victim.read_bytes() == before


def test_report_replaces_an_earlier_report_and_notes_a_deep_npz_header(
    pair: Path, tmp_path: Path
) -> None:
    run = tmp_path / "run"
    (run / "cam_a").mkdir(parents=True)
    shutil.copy(pair / "joint.yaml", run / "joint.yaml")
    T = np.tile(np.eye(4), (5, 1, 1))
    T[:, 0, 3] = np.arange(5)
    deep = "[" * 100_000 + "]" * 100_000  # json.loads: RecursionError
    np.savez(run / "cam_a" / "poses.npz", schema=np.array("acscal/poses"),
             schema_version=np.array(1), T_world_cam=T, timestamps=np.arange(5.0),
             header_json=np.array(deep))  # fmt: skip
    html = run / "report.html"
    html.write_text("<!DOCTYPE html>\n<html><body>an earlier report</body></html>\n")
    res = acscal("report", run, "-o", html)
    assert res.returncode == 0, res.stderr
    assert "nested too deeply" in res.stderr
    assert "an earlier report" not in html.read_text()


# --------------------------------------------------------------------------------------
# Unbounded input


def _alias_bomb(levels: int = 12) -> str:
    """Billion laughs: 9 ** levels strings from a few hundred bytes."""
    lines = ['l0: &l0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def test_a_yaml_alias_bomb_is_refused(pair: Path, tmp_path: Path) -> None:
    bomb = tmp_path / "joint.yaml"
    bomb.write_text(
        _alias_bomb() + "schema: acscal/joint\nschema_version: 1\njoint:\n  position_in_a: *l11\n"
    )
    res = acscal("relpose", "--joint", bomb, "--poses-a", pair / "general_a.tum",
                 "--poses-b", pair / "general_b.tum", "-o", tmp_path / "r.yaml",
                 timeout=60)  # fmt: skip
    assert res.returncode == 2 and "alias bomb" in res.stderr, res.stderr
    assert len(res.stderr) < 1000
    cfg = tmp_path / "run.yaml"
    cfg.write_text(_alias_bomb() + "schema: acscal/run-config\nschema_version: 1\nboard: *l11\n")
    res = acscal("run", cfg, timeout=60)
    assert res.returncode == 2 and "alias bomb" in res.stderr, res.stderr
    _no_traceback(res)


def test_yaml_nested_a_hundred_thousand_deep_is_one_line(tmp_path: Path) -> None:
    # 200 kB that libyaml's own composer recursed on in C until the process crashed
    # (SIGSEGV); nodes are composed in Python, which stops cleanly
    cfg = tmp_path / "run.yaml"
    cfg.write_text("[" * 100_000 + "]" * 100_000)
    res = acscal("run", cfg, timeout=60)
    assert res.returncode == 2 and "not valid YAML" in res.stderr, res.stderr
    _no_traceback(res)


def test_merged_defaults_in_a_run_config_still_load(tmp_path: Path) -> None:
    cfg = tmp_path / "run.yaml"
    cfg.write_text(
        "schema: acscal/run-config\nschema_version: 1\noutput: out\n"
        "board: {cols: 9, rows: 6, square: 0.025}\n"
        "defaults: &cam {model: pinhole}\n"
        "cameras:\n  a: {<<: *cam, images: missing_a}\n  b: {<<: *cam, images: missing_b}\n"
        "joint: {scenario: fixed_joint}\n"
    )
    res = acscal("run", cfg)
    assert res.returncode == 2 and "alias" not in res.stderr
    assert "defaults" in res.stderr or "missing_a" in res.stderr, res.stderr


@pytest.mark.parametrize(
    "kind",
    [
        pytest.param(
            "device",
            marks=pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero"),
        ),
        "fifo",
    ],
)
def test_a_trajectory_that_is_not_a_regular_file_is_refused(
    pair: Path, tmp_path: Path, kind: str
) -> None:
    if kind == "fifo":
        src = tmp_path / "traj.tum"
        os.mkfifo(src)  # nobody writes it: reading would block forever
    else:
        src = Path("/dev/zero")  # reading would never end
    res = acscal("joint", "--fixed-joint", "--poses-a", src, "--poses-b", pair / "fixed_b.tum",
                 "-o", tmp_path / "j.yaml", timeout=60)  # fmt: skip
    assert res.returncode == 2 and "not a regular file" in res.stderr, res.stderr
    assert str(src) in res.stderr


def test_an_npz_declaring_a_huge_array_is_refused_before_loading(
    pair: Path, tmp_path: Path
) -> None:
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header, {"descr": "<f8", "fortran_order": False, "shape": (400_000_000,)}
    )  # 3.2 GB declared, a few bytes stored
    T = np.tile(np.eye(4), (20, 1, 1))
    npz = tmp_path / "poses.npz"
    with zipfile.ZipFile(npz, "w", zipfile.ZIP_DEFLATED) as zf:
        for key, value in (("T_world_cam", T), ("timestamps", np.arange(20.0))):
            buf = io.BytesIO()
            np.save(buf, value)
            zf.writestr(f"{key}.npy", buf.getvalue())
        zf.writestr("unused.npy", header.getvalue() + bytes(64))
    res = acscal("joint", "--fixed-joint", "--poses-a", npz, "--poses-b", pair / "fixed_b.tum",
                 "-o", tmp_path / "j.yaml")  # fmt: skip
    assert res.returncode == 2 and "'unused' declares 3200000000 bytes" in res.stderr
    assert "MiB" in res.stderr


# --------------------------------------------------------------------------------------
# Values out of range


def _scaled_tum(src: Path, dest: Path, factor: float) -> Path:
    rows = []
    for line in src.read_text().splitlines():
        if line.startswith("#") or not line.strip():
            rows.append(line)
            continue
        v = line.split()
        xyz = [repr(float(x) * factor) for x in v[1:4]]
        rows.append(" ".join([v[0], *xyz, *v[4:]]))
    dest.write_text("\n".join(rows) + "\n")
    return dest


@pytest.mark.parametrize(
    ("factor", "words"),
    [(1e70, "beyond the 1e+10"), (1e-100, "all below 1e-20"), (math.inf, "NaN or inf")],
)
def test_trajectory_translations_out_of_range_exit_2(
    pair: Path, tmp_path: Path, factor: float, words: str
) -> None:
    bad = _scaled_tum(pair / "fixed_a.tum", tmp_path / "a.tum", factor)
    res = acscal("joint", "--fixed-joint", "--poses-a", bad, "--poses-b", pair / "fixed_b.tum",
                 "-o", tmp_path / "j.yaml")  # fmt: skip
    assert res.returncode == 2 and words in res.stderr and "a.tum" in res.stderr, res.stderr
    _no_traceback(res)


def test_a_tiny_but_sane_trajectory_scale_still_works(pair: Path, tmp_path: Path) -> None:
    a = _scaled_tum(pair / "fixed_a.tum", tmp_path / "a.tum", 1e-9)
    b = _scaled_tum(pair / "fixed_b.tum", tmp_path / "b.tum", 1e-9)
    res = acscal("joint", "--fixed-joint", "--poses-a", a, "--poses-b", b, "--json",
                 "-o", tmp_path / "j.yaml")  # fmt: skip
    assert res.returncode == 0, res.stderr
    pos = np.array(json.loads(res.stdout)["result"]["joint"]["position_in_a"])
    ref = np.array(yaml.safe_load((pair / "joint.yaml").read_text())["joint"]["position_in_a"])
    assert np.linalg.norm(pos / 1e-9 - ref) < 0.05


def test_a_joint_position_of_1e300_exits_2(pair: Path, tmp_path: Path) -> None:
    doc = yaml.safe_load((pair / "joint.yaml").read_text())
    doc["joint"]["position_in_a"] = [1e300, 0.0, 0.0]
    bad = tmp_path / "joint.yaml"
    bad.write_text(yaml.safe_dump(doc))
    res = acscal("relpose", "--joint", bad, "--poses-a", pair / "general_a.tum",
                 "--poses-b", pair / "general_b.tum", "-o", tmp_path / "r.yaml")  # fmt: skip
    assert res.returncode == 2 and "joint.position_in_a" in res.stderr and "1e+300" in res.stderr
    _no_traceback(res)


# --------------------------------------------------------------------------------------
# Options


def test_options_out_of_range_exit_2(pair: Path, tmp_path: Path) -> None:
    common = ["--poses-a", pair / "general_a.tum", "--poses-b", pair / "general_b.tum"]
    for extra, option in (
        (["--reference", "-1"], "--reference"),
        (["--max-dt", "0"], "--max-dt"),
        (["--max-dt", "-0.5"], "--max-dt"),
    ):
        res = acscal("relpose", "--joint", pair / "joint.yaml", *common, *extra,
                     "-o", tmp_path / "r.yaml")  # fmt: skip
        assert res.returncode == 2 and option in res.stderr, (extra, res.stderr)
    res = acscal("relpose", "--joint", pair / "joint.yaml", *common, "--reference", "999",
                 "-o", tmp_path / "r.yaml")  # fmt: skip
    assert res.returncode == 2 and "999" in res.stderr
    for scale in ("0", "-1", "1e300"):
        res = _export(pair, tmp_path / "x.yaml", "opencv", "--scale", scale)
        assert res.returncode == 2 and "--scale" in res.stderr, res.stderr
    assert not (tmp_path / "r.yaml").exists() and not (tmp_path / "x.yaml").exists()


def test_a_bare_acscal_prints_the_help() -> None:
    res = acscal()
    assert res.returncode == 0, res.stderr
    assert "Commands" in res.stdout and "relpose" in res.stdout and "error" not in res.stderr


# --------------------------------------------------------------------------------------
# A run folder inside its own image folder


def test_a_run_folder_inside_its_image_folder_does_not_rerun(tmp_path: Path) -> None:
    from sample_data_gen.render import render_scenario

    render_scenario(tmp_path / "images", "fixed_joint", seed=0, frames=6, size=(480, 360))
    cam_a = tmp_path / "images" / "fixed_joint" / "cam_a"
    cfg = cam_a / "run.yaml"  # the config, and the run's outputs, inside A's image folder
    cfg.write_text(
        "schema: acscal/run-config\nschema_version: 1\noutput: run\n"
        "board: {cols: 9, rows: 6, square: 0.025}\n"
        "cameras:\n  a: {images: ., model: pinhole}\n  b: {images: ../cam_b}\n"
        "joint: {scenario: fixed_joint}\n"
    )
    first = acscal("run", cfg, "--only", "intrinsics")
    assert first.returncode == 0, first.stderr
    assert "intrinsics a: ran" in first.stdout
    second = acscal("run", cfg, "--only", "intrinsics")
    assert second.returncode == 0, second.stderr
    assert "intrinsics a: skipped" in second.stdout and "intrinsics b: skipped" in second.stdout
