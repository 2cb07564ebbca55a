"""The scripts in ``examples/`` run as a user runs them, and print what they promise."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from acs_cli.io.rig import RigArtifact

ROOT = Path(__file__).resolve().parents[2]


def _run(script: str, *args: str | Path) -> subprocess.CompletedProcess[str]:
    # the checkout's acs_cli and sample_data_gen first, whatever is installed
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return subprocess.run(
        [sys.executable, str(ROOT / "examples" / script), *map(str, args)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env=dict(os.environ, PYTHONPATH=path),
        timeout=120,
    )


def test_calibrate_rig_from_arrays(tmp_path: Path) -> None:
    out = tmp_path / "out"
    proc = _run("calibrate_rig_from_arrays.py", "--out", out)
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout
    # part 1: every joint with its std beside the truth, the unknown scale, rig.yaml
    for name, kind in (("shoulder", "ball"), ("elbow", "hinge"), ("wrist", "rigid")):
        assert f"joint {name} ({kind}" in text
    assert text.count("std [") >= 4 + 4  # 4 joint positions, 4 cameras
    assert "true [" in text and "axis in upper" in text
    assert "scale 0." in text or "scale 1." in text or "scale 2." in text
    assert f"wrote {out / 'rig.yaml'}" in text
    rig = RigArtifact.load(out / "rig.yaml")
    assert set(rig.cameras) == {"base", "upper", "fore", "hand"}
    assert set(rig.joints) == {"shoulder", "elbow", "wrist"}
    assert "refused (DegenerateMotionError)" in text
    # part 2: two recordings, each in a shared world; the knee trial's world is not tied
    assert "hip centre in pelvis" in text and "knee axis in femur" in text
    assert "world hip: bodies pelvis, femur, tied to the reference: True" in text
    assert "world knee: bodies femur, tibia, tied to the reference: False" in text
    assert "tibia T_cam_ref: None" in text
