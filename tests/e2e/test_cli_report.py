"""``acscal trajectory`` and ``acscal report`` end to end, and the report in headless Chromium.

One module fixture renders a small image set (fixed-joint and general motion), runs
``acscal run`` on it (which ends with ``report.html``) and is shared by the tests.
"""

from __future__ import annotations

import base64
import dataclasses
import html as html_lib
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from cli_runner import acscal

from acs_cli.core import se3
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.trajectory import read_trajectory
from sample_data_gen.render import render_scenario
from sample_data_gen.writer import SCENARIOS, make_sequence, rig_for_seed, write_scenario

FIGURES = {
    "rig_trajectory.png",
    "rig_reference.png",
    "joint_residuals.png",
    "joint_angles.png",
    "reprojection.png",
    "corner_errors.png",
    "coverage.png",
}
DATA_IMG = re.compile(r'<img src="data:image/png;base64,([A-Za-z0-9+/=]+)"')

CONFIG = """\
schema: acscal/run-config
schema_version: 1
output: ../run
board: {cols: 9, rows: 6, square: 0.025}
cameras:
  a: {images: ../images/fixed_joint/cam_a, model: pinhole}
  b: {images: ../images/fixed_joint/cam_b}
joint: {scenario: fixed_joint, method: refined}
relpose:
  images: {a: ../images/general/cam_a, b: ../images/general/cam_b}
  method: refined
"""


def load(path: Path) -> dict:
    return yaml.safe_load(path.read_text(encoding="utf-8"))


def _without_data(html: str) -> str:
    return DATA_IMG.sub("<img>", html)


def _text(html: str) -> str:
    """The page's text: tags out, entities decoded."""
    return html_lib.unescape(re.sub(r"<[^>]+>", " ", _without_data(html)))


def _verdict_rows(html: str) -> dict[str, str]:
    """Each stage's verdict in the verdict table, by stage."""
    rows = re.findall(r'<tr><td>([^<]+)</td><td class="status-(pass|check|fail)">', html)
    return {html_lib.unescape(stage): status for stage, status in rows}


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser"):
        found = shutil.which(name)
        if found:
            return found
    return None


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """Render 10 frames of each motion, run the whole chain once: the run folder."""
    root = tmp_path_factory.mktemp("acs_report")
    for scenario in ("fixed_joint", "general"):
        render_scenario(root / "images", scenario, seed=1, frames=10, size=(640, 480))
    config = root / "configs" / "run.yaml"
    config.parent.mkdir()
    config.write_text(CONFIG, encoding="utf-8")
    res = acscal("run", config)
    assert res.returncode == 0, res.stdout + res.stderr
    return {"root": root, "dir": root / "run", "stdout": res.stdout}


# --------------------------------------------------------------------------- acscal run


def test_run_ends_with_a_self_contained_report(run: dict[str, object]) -> None:
    run_dir = Path(str(run["dir"]))
    assert "report: written" in str(run["stdout"])
    html = (run_dir / "report.html").read_text(encoding="utf-8")
    assert {p.name for p in (run_dir / "report_files").iterdir()} == FIGURES
    assert len(DATA_IMG.findall(html)) == len(FIGURES)
    rest = _without_data(html)
    assert "http" not in rest and "<script" not in rest and "<link" not in rest
    for section in ("Warnings", "Estimates and standard deviations", "Reprojection errors"):
        assert section in rest


# --------------------------------------------------------------------------- trajectory


def test_trajectory_of_the_run_matches_the_rendered_truth(
    run: dict[str, object], tmp_path: Path
) -> None:
    run_dir = Path(str(run["dir"]))
    out = tmp_path / "traj"
    res = acscal(
        "trajectory", "--joint", run_dir / "joint.yaml", "--relpose", run_dir / "relpose.yaml",
        "--poses-a", run_dir / "cam_a" / "poses_general.npz",
        "--poses-b", run_dir / "cam_b" / "poses_general.npz", "-o", out,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    ta, tb, tj = (read_trajectory(out / f"{n}.tum", "tum") for n in ("cam_a", "cam_b", "joint"))
    doc = load(out / "trajectory.yaml")
    assert doc["schema"] == "acscal/trajectory"
    n = len(ta)
    assert len(tb) == n == len(tj) == len(doc["consistency"]["frames"]["distance"])
    k = doc["reference"]["index"]
    np.testing.assert_allclose(ta.T_world_cam[k], np.eye(4), atol=1e-12)
    # the joint's pose: camera A's orientation, at T_world_a @ o_a
    o_a = np.asarray(doc["joint"]["position_in_a"])
    np.testing.assert_allclose(tj.T_world_cam[:, :3, :3], ta.T_world_cam[:, :3, :3], atol=1e-9)
    np.testing.assert_allclose(
        tj.T_world_cam[:, :3, 3], se3.transform_points(ta.T_world_cam, o_a), atol=1e-9
    )
    # the joint from A and from B agree to a few millimetres (rendered images, 640x480)
    assert doc["consistency"]["rms"] < 0.005
    # each frame's relative pose T_a_b against the renderer's truth
    truth = load(Path(str(run["root"])) / "images" / "general" / "truth.yaml")
    frames = np.round(ta.timestamps).astype(int)
    T_a_b_true = np.asarray(truth["T_a_b"], dtype=float)[frames]
    T_a_b = se3.invert_transforms(ta.T_world_cam) @ tb.T_world_cam
    R_err = np.swapaxes(T_a_b_true[:, :3, :3], 1, 2) @ T_a_b[:, :3, :3]
    assert se3.rotation_angle_deg(R_err).max() < 1.0
    assert np.linalg.norm(T_a_b[:, :3, 3] - T_a_b_true[:, :3, 3], axis=1).max() < 0.02


def test_trajectory_under_unknown_scale_is_in_a_units(tmp_path: Path) -> None:
    seed, frames, mu_a, mu_b = 3, 20, 0.8, 3.2
    for scenario in ("fixed_joint", "general"):
        write_scenario(tmp_path / scenario, scenario, seed=seed, frames=frames, mu_a=mu_a,
                       mu_b=mu_b)  # fmt: skip
    g = tmp_path / "general"
    poses: list[str | Path] = ["--poses-a", g / "cam_a.tum", "--poses-b", g / "cam_b.tum"]
    f = tmp_path / "fixed_joint"
    assert acscal("joint", "--fixed-joint", "--poses-a", f / "cam_a.tum", "--poses-b",
                  f / "cam_b.tum", "-o", tmp_path / "joint.yaml").returncode == 0  # fmt: skip
    res = acscal("relpose", "--unknown-scale", "--joint", tmp_path / "joint.yaml", *poses,
                 "--reference", "3", "-o", tmp_path / "relpose.yaml")  # fmt: skip
    assert res.returncode == 0, res.stderr
    out = tmp_path / "traj"
    res = acscal("trajectory", "--relpose", tmp_path / "relpose.yaml", *poses, "-o", out)
    assert res.returncode == 0, res.stderr
    doc = load(out / "trajectory.yaml")
    assert doc["reference"]["index"] == 3
    assert doc["scale"]["phi_ba"] == pytest.approx(mu_b / mu_a, rel=1e-9)
    assert doc["consistency"]["max"] < 1e-9
    assert "A units" in doc["units"]["length"]
    # noiseless: camera B's path is the truth, in A units (mu_a x metres)
    rng = np.random.default_rng([seed, 1, SCENARIOS.index("general")])
    seq = make_sequence(rng, rig_for_seed(seed), "general", frames)
    T_r_a = se3.invert_transforms(seq.T_wa_a[3]) @ seq.T_wa_a
    T_r_b = T_r_a @ seq.T_a_b
    tb = read_trajectory(out / "cam_b.tum", "tum")
    np.testing.assert_allclose(tb.T_world_cam[:, :3, 3], mu_a * T_r_b[:, :3, 3], atol=1e-8)
    np.testing.assert_allclose(tb.T_world_cam[:, :3, :3], T_r_b[:, :3, :3], atol=1e-8)

    # the report of this folder (no images): trajectory and residuals, the rest skipped
    report = tmp_path / "report.html"
    res = acscal("report", tmp_path, "-o", report)
    assert res.returncode == 0, res.stderr
    names = {p.name for p in (tmp_path / "report_files").iterdir()}
    assert names == {
        "rig_trajectory.png",
        "rig_reference.png",
        "joint_residuals.png",
        "joint_angles.png",
    }
    html = report.read_text(encoding="utf-8")
    assert len(DATA_IMG.findall(html)) == 4
    # its angle panel is angles.csv's, zero at the reference frame (issue 22, item 1)
    from acs_cli.io.angles import read_angles_csv
    from acs_cli.stages.report import build_report

    (panel,) = build_report(tmp_path).angles
    csv = read_angles_csv(out / "angles.csv")["joint"]
    got = np.column_stack([csv[f"rotvec_{c}_deg"] for c in "xyz"])
    np.testing.assert_allclose(panel.values, got, atol=1e-6)
    assert panel.zero == pytest.approx(float(csv["time"][3]))
    assert "phi_ba" in html and "No poses with corners" in html


def test_trajectory_input_errors(run: dict[str, object], tmp_path: Path) -> None:
    run_dir = Path(str(run["dir"]))
    rel = run_dir / "relpose.yaml"
    # trajectories that do not hold the reference instant: exit 2, one line
    tum = (run_dir / "cam_a" / "poses_general.tum").read_text().splitlines()
    data = [ln for ln in tum if ln and not ln.startswith("#")]
    late = tmp_path / "late_a.tum"
    notes = [ln for ln in tum if ln.startswith("#")]  # keep "times are frame numbers"
    late.write_text("\n".join(notes + data[3:]) + "\n")
    res = acscal("trajectory", "--relpose", rel, "--poses-a", late, "--poses-b",
                 run_dir / "cam_b" / "poses_general.tum", "-o", tmp_path / "t")  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert "reference instant" in res.stderr and "Traceback" not in res.stderr
    # another stage's artifact as --relpose
    res = acscal("trajectory", "--relpose", run_dir / "joint.yaml", "--poses-a", late,
                 "--poses-b", late, "-o", tmp_path / "t")  # fmt: skip
    assert res.returncode == 2 and "acscal/relpose" in res.stderr
    # the same poses from another file than relpose's (its TUM twin): a warning, still written
    res = acscal("trajectory", "--relpose", rel, "--poses-a",
                 run_dir / "cam_a" / "poses_general.tum", "--poses-b",
                 run_dir / "cam_b" / "poses_general.npz", "-o", tmp_path / "u")  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "differs from the poses_a" in res.stderr
    assert (tmp_path / "u" / "joint.tum").is_file()


# --------------------------------------------------------------------------- report


def test_report_command_writes_html_and_pngs(run: dict[str, object], tmp_path: Path) -> None:
    out = tmp_path / "out" / "calib.html"
    res = acscal("report", Path(str(run["dir"])), "-o", out)
    assert res.returncode == 0, res.stderr
    assert f"{len(FIGURES)} figures" in res.stdout
    folder = tmp_path / "out" / "calib_files"
    assert {p.name for p in folder.iterdir()} == FIGURES
    html = out.read_text(encoding="utf-8")
    inlined = {base64.b64decode(m) for m in DATA_IMG.findall(html)}
    assert inlined == {p.read_bytes() for p in folder.iterdir()}
    assert all(b.startswith(b"\x89PNG\r\n\x1a\n") for b in inlined)
    assert all(len(b) < 400_000 for b in inlined)
    # every estimate with its std and unit; the warnings of the run
    assert "camera A fx" in html and "joint in B (o_b) z" in html and "R_a_b yaw" in html
    assert "no partner" in html or "unpaired samples" in html or "No warnings" in html


def test_report_opens_with_a_verdict_against_stated_thresholds(run: dict[str, object]) -> None:
    html = (Path(str(run["dir"])) / "report.html").read_text(encoding="utf-8")
    text = _text(html)
    # the verdict comes first, every stage of the run marked pass, check or fail
    assert html.index('id="verdict"') < html.index('id="artifacts"')
    assert re.search(r"Overall: (pass|check|fail) \(", text)
    stages = _verdict_rows(html)
    for stage in ("intrinsics, camera A", "intrinsics, camera B", "poses, camera A", "joint",
                  "relpose", "bundle adjustment (joint.yaml), camera A",
                  "bundle adjustment (relpose.yaml), camera B"):  # fmt: skip
        assert stage in stages, stages
    # good rendered data: corners well fitted, the joint well determined
    assert "reprojection RMS 0.0" in text and "(fail)" not in text
    assert re.search(r"joint in A: joint std / joint distance [0-9.]+% \(pass\)", text)
    # the thresholds are in the report itself
    for label in ("reprojection RMS", "image coverage", "joint residual / expected from the "
                  "pose noise", "joint std / joint distance", "<= 0.5 px", ">= 50%"):  # fmt: skip
        assert label in text, label
    # coverage under half: a check in the verdict and a warning
    for cam, pct in re.findall(r"intrinsics, camera ([AB]) \w+ [^|]*?image coverage ([0-9.]+)%",
                               text):  # fmt: skip
        if float(pct) < 50:
            assert f"camera {cam}: the detected corners cover {pct}% of the image cells" in text
            assert stages[f"intrinsics, camera {cam}"] != "pass"


def test_report_says_what_is_final_fixed_and_exported(run: dict[str, object]) -> None:
    html = (Path(str(run["dir"])) / "report.html").read_text(encoding="utf-8")
    text = _text(html)
    # the bundle-adjusted intrinsics of the last stage are the final ones, and its joint
    assert "relpose.yaml: quality.bundle_adjustment.a" in text
    assert "relpose.yaml: joint" in text
    assert "Exported: no export file is recorded in the run folder" in text
    # k3, held by the pinhole calibration and the bundle adjustments: "fixed", never std 0
    k3 = re.findall(r'<td>camera [AB] k3[^<]*</td><td class="num">[^<]*</td>'
                    r'<td class="num">([^<]*)</td>', html)  # fmt: skip
    assert len(k3) == 6 and set(k3) == {"fixed"}, k3
    # nothing zero by construction
    assert "joint gap" not in text
    assert "besides the reference (where they agree by construction)" in text
    # the per-corner errors: a scatter, the radial trend, a histogram per camera
    assert "Per-corner reprojection errors" in text and "distance from the principal point" in text
    png = Path(str(run["dir"])) / "report_files" / "corner_errors.png"
    assert png.stat().st_size > 20_000


def test_report_of_45_views_with_partial_corners(run: dict[str, object], tmp_path: Path) -> None:
    """45 calibration views (every one labelled, and in a table), poses whose corners are seen
    in the top-left quarter only (NaN elsewhere: a low coverage, warned about) and an
    export that holds the calibration, not the bundle-adjusted intrinsics."""
    run_dir = Path(str(run["dir"]))
    cam = tmp_path / "many" / "cam_a"
    cam.mkdir(parents=True)
    doc = load(run_dir / "cam_a" / "intrinsics.yaml")
    doc["per_view_rms_px"] = {f"view_{i:03d}_left.png": 0.01 + 0.001 * i for i in range(45)}
    doc["exports"] = {"opencv": "intrinsics_opencv.yaml"}
    (cam / "intrinsics.yaml").write_text(yaml.safe_dump(doc), encoding="utf-8")
    (cam / "intrinsics_opencv.yaml").write_text("%YAML:1.0\n", encoding="utf-8")
    poses = PosesArtifact.load(run_dir / "cam_a" / "poses.npz")
    assert poses.corners is not None
    corners = poses.corners.copy()
    corners[(corners[..., 0] > 320) | (corners[..., 1] > 240)] = np.nan
    dataclasses.replace(poses, corners=corners).save(cam / "poses.npz")

    res = acscal("report", cam.parent)
    assert res.returncode == 0, res.stderr
    names = {p.name for p in (cam.parent / "report_files").iterdir()}
    assert names == {"reprojection.png", "corner_errors.png", "coverage.png"}
    html = (cam.parent / "report.html").read_text(encoding="utf-8")
    text = _text(html)
    # every view in the table, worst first, beside the 9 posed images
    assert "Table of the 54 views and posed images, worst first" in text
    listed = re.findall(r"<td>(view_\d{3}_left\.png)</td>", html)
    assert listed == [f"view_{i:03d}_left.png" for i in range(44, -1, -1)]
    # the chart grows with the views: every one gets a labelled bar
    chart = cv2.imread(str(cam.parent / "report_files" / "reprojection.png"))
    assert chart is not None and chart.shape[0] > 45 * 0.16 * 100
    # at most a quarter of the image covered: a warning, and no pass in the verdict
    got = re.search(r"camera A: the detected corners cover ([0-9.]+)% of the image cells "
                    r"\(under half\)", text)  # fmt: skip
    assert got is not None, text
    pct = float(got.group(1))
    status = "check" if pct == 25 else "fail"
    assert 0 < pct <= 25 and f"image coverage {got.group(1)}% ({status})" in text
    assert _verdict_rows(html)["intrinsics, camera A"] == status
    assert "intrinsics_opencv.yaml (opencv): the intrinsics of cam_a/intrinsics.yaml" in text
    assert "cam_a/intrinsics.yaml" in text and "no bundle adjustment refined it" in text


def test_report_degrades_gracefully(run: dict[str, object], tmp_path: Path) -> None:
    run_dir = Path(str(run["dir"]))
    partial = tmp_path / "partial"
    (partial / "cam_a").mkdir(parents=True)
    (partial / "cam_b").mkdir()
    shutil.copy(run_dir / "joint.yaml", partial / "joint.yaml")
    for cam in ("cam_a", "cam_b"):
        shutil.copy(run_dir / cam / "poses.npz", partial / cam / "poses.npz")
    (partial / "relpose.yaml").write_text("schema: acscal/relpose\n: not yaml [\n")
    res = acscal("report", partial)
    assert res.returncode == 0, res.stderr
    names = {p.name for p in (partial / "report_files").iterdir()}
    assert names == {"joint_residuals.png", "reprojection.png", "coverage.png"}
    html = (partial / "report.html").read_text(encoding="utf-8")
    assert "relpose.yaml could not be read" in html and "Trajectory skipped" in html


def test_run_report_hook_lists_a_failure_and_never_raises(
    run: dict[str, object], tmp_path: Path
) -> None:
    """What ``acscal run`` calls at its end (and when a stage stops on degenerate motion)."""
    from acs_cli.stages.run import write_run_report

    copy = tmp_path / "run"
    shutil.copytree(Path(str(run["dir"])), copy, symlinks=True)
    seen: list[object] = []
    res = write_run_report(copy, seen.append, ["relpose failed: the joint path is straight"])
    assert res.status == "written" and seen == [res] and res.outputs == [copy / "report.html"]
    html = (copy / "report.html").read_text(encoding="utf-8")
    assert "run: relpose failed: the joint path is straight" in html
    empty = tmp_path / "empty"
    empty.mkdir()
    res = write_run_report(empty)
    assert res.status == "failed" and "no acscal artifact" in res.warnings[0]


def test_report_needs_a_run_folder(tmp_path: Path) -> None:
    empty = tmp_path / "empty"
    empty.mkdir()
    for folder in (empty, tmp_path / "missing"):
        res = acscal("report", folder)
        assert res.returncode == 2, res.stderr
        assert len(res.stderr.strip().splitlines()) == 1 and "Traceback" not in res.stderr
    assert not (empty / "report.html").exists()


def test_help_has_examples() -> None:
    for cmd in ("trajectory", "report"):
        res = acscal(cmd, "--help")
        assert res.returncode == 0 and "Example" in res.stdout, res.stdout


# --------------------------------------------------------------------------- Chromium


@pytest.mark.skipif(
    _chromium() is None, reason="no chromium binary on PATH (apt-get install chromium)"
)
def test_report_renders_in_headless_chromium(run: dict[str, object], tmp_path: Path) -> None:
    browser = _chromium()
    if browser is None:  # for the type checker: the mark above skips this case
        raise RuntimeError("chromium vanished from PATH during the run")
    report = Path(str(run["dir"])) / "report.html"
    html = report.read_text(encoding="utf-8")
    assert len(DATA_IMG.findall(html)) == len(FIGURES)
    assert "http" not in _without_data(html)
    shot = tmp_path / "shot.png"
    cmd = [
        browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
        "--no-first-run", "--disable-background-networking", "--disable-component-update",
        "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}",
        "--window-size=1200,5000", report.resolve().as_uri(),
    ]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert res.returncode == 0 and shot.is_file(), res.stderr[-2000:]
    img = cv2.imread(str(shot), cv2.IMREAD_COLOR)
    assert img is not None and img.shape[:2] == (5000, 1200)
    pixels = img.reshape(-1, 3).astype(int)
    non_white = float(np.mean(pixels.min(axis=1) < 235))
    colours = np.unique(pixels[:, 0] * 65536 + pixels[:, 1] * 256 + pixels[:, 2]).size
    # the figures' blue (camera A, #1f77b4) and orange (camera B, #ff7f0e), in BGR
    blue = int(np.sum(np.abs(pixels - [180, 119, 31]).max(axis=1) < 40))
    orange = int(np.sum(np.abs(pixels - [14, 127, 255]).max(axis=1) < 40))
    print(f"non-white {non_white:.1%}, {colours} colours, {blue} blue, {orange} orange px")
    assert non_white > 0.05
    assert colours > 500
    assert blue > 2000 and orange > 500
