"""``python -m sample_data_gen.demo OUT`` (what ``make demo`` runs), end to end."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]
NUMBER = r"[+-]\d+\.\d+"
VECTOR = rf"\[{NUMBER}, {NUMBER}, {NUMBER}\]"
SEP = r"\s*│\s*"  # a table cell border, with the padding around it
RATIO = r"\[?[+-]?\d+\.\d+\]?"  # a number, or a one-number vector


# in `make test`, although it takes the longest: README's first command must work
def test_demo_prints_both_tables(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    env = dict(os.environ, COLUMNS="120", NO_COLOR="1")
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "sample_data_gen.demo",
            str(out),
            "--frames",
            "12",
            "--no-markerless",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        timeout=600,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    text = res.stdout

    # the trajectory table (Algorithms I-IV beside the truth)
    assert "acscal demo: estimates beside the truth" in text
    assert re.search(rf"joint in A, overlap \(Alg I\){SEP}{VECTOR}{SEP}{VECTOR}{SEP}{VECTOR}", text)
    assert re.search(rf"phi_ba = mu_b / mu_a \(Alg IV\){SEP}{RATIO}{SEP}{RATIO}{SEP}{RATIO}", text)

    # the image-chain table, from `acscal run` on the copied configs
    assert "acscal run from rendered images" in text
    assert (out / "configs" / "fixed_joint.yaml").is_file()
    assert (out / "run_fixed_joint" / "relpose.yaml").is_file()
    assert (out / "run_overlap" / "joint.yaml").is_file()
    # the overlap run reads the two cameras' videos (make demo: one calibration from video)
    intr = yaml.safe_load((out / "run_overlap" / "cam_a" / "intrinsics.yaml").read_text())
    assert intr["video"]["decoded"] == 12
    assert (out / "images" / "overlap" / "cam_a.mkv").is_file()
    assert (out / "images" / "general" / "truth.yaml").is_file()
    errors = [
        float(m)
        for m in re.findall(rf"{VECTOR}{SEP}{VECTOR}{SEP}\d+\.\d+ mm = (\d+\.\d+)% of \|O\|", text)
    ]
    assert len(errors) == 4, text  # joint in A and B, fixed joint and overlap
    assert max(errors) < 3.0, errors
    assert re.search(r"\d+\.\d+ deg \(rotation angle\)", text)
    assert "artifacts in" in text
