"""The report of a rig run (issue 22, item 5): a rig's report is about the rig.

One module fixture runs the rig stage on the sample rig of five cameras (``cam0 -(rigid)-
cam1``, ``cam0 -(ball)- cam2 -(hinge)- cam3 -(rigid)- cam4``, poses files only) with one
gross outlier in cam2's poses; the tests read its run folder into the report's model.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from acs_cli.io.config import load_run_config
from acs_cli.io.rig import RigArtifact
from acs_cli.io.rig_residuals import RESIDUALS_FILE, read_joint_residuals
from acs_cli.io.trajectory import read_trajectory, write_tum
from acs_cli.report.render import render_report
from acs_cli.stages.report import build_report
from acs_cli.stages.rig import run_rig
from sample_data_gen.writer import write_rig_recording

OUTLIER = 17  # the frame at which cam2's pose is 0.5 m off


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("rig_report")
    write_rig_recording(root, seed=5, frames=40)
    t = read_trajectory(root / "cam2.tum")
    T = t.T_world_cam.copy()
    T[OUTLIER, :3, 3] += 0.5
    write_tum(root / "cam2.tum", t.timestamps, T)
    run_rig(load_run_config(root / "config.yaml"))
    return root / "out"


def test_the_rig_stage_writes_each_joints_residual_per_frame(run_dir: Path) -> None:
    rig = RigArtifact.load(run_dir / "rig.yaml")
    got = {r.joint: r for r in read_joint_residuals(run_dir / RESIDUALS_FILE)}
    assert set(got) == set(rig.joints)
    for name, j in rig.joints.items():
        r = got[name]
        assert r.times.size == j.frames_used + j.frames_rejected
        assert int((~r.used).sum()) == j.frames_rejected
        # rig.yaml's residual_rms: the point rows (ball, hinge) or the translation rows
        length = r.values["pos" if j.model.has_point else "trans"]
        assert np.sqrt(np.mean(length[r.used] ** 2)) == pytest.approx(j.residual_rms, rel=1e-9)
    assert set(got["j23"].values) == {"pos", "rot"} and set(got["r01"].values) == {"rot", "trans"}
    hinge = got["j23"]
    wobble = rig.joints["j23"].wobble_rms_deg
    assert np.sqrt(np.mean(hinge.values["rot"][hinge.used] ** 2)) == pytest.approx(wobble)
    # the outlier: rejected by both joints of cam2, at its time
    for name in ("j02", "j23"):
        assert got[name].times[~got[name].used] == pytest.approx([OUTLIER / 30.0])


def test_a_rigs_report_is_about_the_rig(run_dir: Path) -> None:
    model = build_report(run_dir)
    # none of the pair's stages' skip notes (joint.yaml, relpose.yaml, images)
    assert model.notes == [] and model.section_notes == {}
    assert model.rig is not None and model.rig.from_images == []
    # one residual series per joint and kind, in mm and deg, the outlier marked
    titles = [s.title.split(" ", 1)[0] for s in model.residuals]
    assert titles == ["r01", "r01", "j02", "j23", "j23", "r34", "r34"]
    assert [s.unit for s in model.residuals] == ["mm", "deg", "mm", "mm", "deg", "mm", "deg"]
    marked = {s.title.split(" ", 1)[0]: s.x[s.rejected] for s in model.residuals}
    assert marked["j02"] == pytest.approx([OUTLIER / 30.0]) and marked["r01"].size == 0
    # one angle series per ball or hinge joint: a hinge's angle, a ball's rotation vector
    assert [a.title.split(" ", 1)[0] for a in model.angles] == ["j02", "j23"]
    ball, hinge = model.angles
    assert ball.values.shape == (40, 3) and hinge.values.shape == (40, 1)
    assert ball.zero == 0.0 and np.allclose(ball.values[0], 0.0, atol=1e-9)
    assert ball.x[ball.rejected] == pytest.approx([OUTLIER / 30.0])
    lo, hi = RigArtifact.load(run_dir / "rig.yaml").joints["j23"].angle_range_deg or (0, 0)
    used = ~hinge.rejected
    assert hinge.values[used].min() == pytest.approx(lo, abs=1.0)
    assert hinge.values[used].max() == pytest.approx(hi, abs=1.0)
    # the rig drawn at a few instants, in the reference camera's frame at each
    view = model.rig
    assert 2 <= view.instants.size <= 7 and view.instants[0] == 0.0
    assert np.allclose(view.at_instants["cam0"], 0.0, atol=1e-9)
    assert not model.reprojection and not model.coverage and not model.corner_errors


def test_the_rendered_rig_report_has_its_sections_only(run_dir: Path) -> None:
    page = render_report(build_report(run_dir), dpi=40)
    assert set(page.pngs) == {"rig", "residuals", "angles"}
    html = page.html
    heads = re.findall(r"<h2[^>]*>(.*?)</h2>", html)
    assert "Joint angles per frame" in heads and "Joint-constraint residuals per frame" in heads
    for absent in ("Reprojection errors", "Image coverage", "Sections skipped"):
        assert not any(absent in h for h in heads), heads
    assert "No joint.yaml" not in html and "No relpose.yaml" not in html
    assert html.count("none ran from images here") == 1
    assert "Rigid joints (r01, r34) have no angle." in html


def test_a_rig_run_without_its_residuals_file_says_so_once(run_dir: Path, tmp_path: Path) -> None:
    old = tmp_path / "old"
    old.mkdir()
    (old / "rig.yaml").write_bytes((run_dir / "rig.yaml").read_bytes())
    model = build_report(old)  # a rig run of an earlier acscal: no per-frame files
    assert len(model.notes) == 2, model.notes
    assert "No joint_residuals.csv" in model.notes[0] and "No trajectories/" in model.notes[1]
    assert not model.residuals and not model.angles and model.rig is not None
