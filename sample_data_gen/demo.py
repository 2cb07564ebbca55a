"""``make demo``: a synthetic ACS calibrated with the real ``acscal`` commands.

``python -m sample_data_gen.demo OUT_DIR`` writes the sample set (when missing), runs
``acscal joint`` and ``acscal relpose`` as a user would (paper's method and ours, known and
unknown scale, self-calibration) and prints each result beside the truth.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from rich.console import Console
from rich.table import Table

from sample_data_gen.writer import write_sample_set

ACSCAL = Path(sys.executable).with_name("acscal")
console = Console(highlight=False, width=None if sys.stdout.isatty() else 120)


def _run(*args: str | Path) -> None:
    cmd = [str(ACSCAL), *map(str, args)]
    console.print(f"[bold]$ acscal {' '.join(map(str, args))}[/]")
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        console.print(res.stdout + res.stderr)
        raise SystemExit(f"demo: acscal failed with exit code {res.returncode}")


def _load(path: Path) -> dict[str, Any]:
    return dict(yaml.safe_load(path.read_text()))


def _v(x: Any, digits: int = 3) -> str:
    return "[" + ", ".join(f"{float(v):+.{digits}f}" for v in np.ravel(x)) + "]"


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sample_data_gen.demo", description=__doc__)
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    out: Path = args.out_dir
    data = out / "data"
    if not (data / "general_scaled" / "truth.yaml").exists():
        console.print(f"writing the sample data set into {data}")
        write_sample_set(data, seed=args.seed)
    res = out / "results"
    res.mkdir(parents=True, exist_ok=True)

    def poses(scn: str) -> list[str | Path]:
        return ["--poses-a", data / scn / "cam_a.tum", "--poses-b", data / scn / "cam_b.tum"]

    for method in ("paper", "refined"):
        _run("joint", "--fixed-joint", *poses("fixed_joint"), "--method", method,
             "-o", res / f"joint_fixed_{method}.yaml")  # fmt: skip
        _run("joint", "--overlap", *poses("overlap"), "--method", method,
             "-o", res / f"joint_overlap_{method}.yaml")  # fmt: skip
        _run("relpose", "--joint", res / f"joint_fixed_{method}.yaml", *poses("general"),
             "--method", method, "-o", res / f"relpose_{method}.yaml")  # fmt: skip
        _run("joint", "--fixed-joint", *poses("fixed_joint_scaled"), "--method", method,
             "-o", res / f"joint_fixed_scaled_{method}.yaml")  # fmt: skip
        _run("relpose", "--unknown-scale", "--joint", res / f"joint_fixed_scaled_{method}.yaml",
             *poses("general_scaled"), "--method", method,
             "-o", res / f"relpose_scaled_{method}.yaml")  # fmt: skip
    _run("relpose", "--self-calibrate", "--unknown-scale", *poses("general_scaled"),
         "-o", res / "relpose_selfcal_scaled.yaml")  # fmt: skip
    _run("export", res / "relpose_refined.yaml", "--format", "kalibr",
         "-o", res / "camchain.yaml")  # fmt: skip

    truth = _load(data / "general" / "truth.yaml")
    truth_s = _load(data / "general_scaled" / "truth.yaml")
    mu_b = float(truth_s["scale"]["mu_b"])
    table = Table(title="acscal demo: estimates beside the truth (lengths in metres)")
    table.add_column("quantity")
    table.add_column("truth")
    table.add_column("paper's method")
    table.add_column("acscal (refined)")

    def both(name: str, key: str, scale: float = 1.0) -> tuple[str, str]:
        vals = []
        for m in ("paper", "refined"):
            doc = _load(res / f"{name}_{m}.yaml")
            node: Any = doc
            for k in key.split("."):
                node = node[k]
            vals.append(_v(np.asarray(node, dtype=float) / scale))
        return vals[0], vals[1]

    tj = truth["joint"]
    table.add_row("joint in A, fixed joint (Alg II)", _v(tj["position_in_a"]),
                  *both("joint_fixed", "joint.position_in_a"))  # fmt: skip
    table.add_row("joint in B, fixed joint (Alg II)", _v(tj["position_in_b"]),
                  *both("joint_fixed", "joint.position_in_b"))  # fmt: skip
    table.add_row("joint in A, overlap (Alg I)", _v(tj["position_in_a"]),
                  *both("joint_overlap", "joint.position_in_a"))  # fmt: skip
    tr = truth["relative_pose"]
    table.add_row("roll/pitch/yaw of R_a_b, deg (Alg III)", _v(tr["rpy_deg"], 2),
                  *both("relpose", "relative_pose.rpy_deg"))  # fmt: skip
    table.add_row("B's origin in A (Alg III)", _v(tr["translation_b_in_a"]),
                  *both("relpose", "relative_pose.translation_b_in_a"))  # fmt: skip
    table.add_row("B's origin in A, unknown scale (Alg IV)", _v(tr["translation_b_in_a"]),
                  *both("relpose_scaled", "relative_pose.translation_b_in_a", mu_b))  # fmt: skip
    table.add_row("phi_ba = mu_b / mu_a (Alg IV)", f"{truth_s['scale']['phi_ba']:.4f}",
                  *both("relpose_scaled", "scale.phi_ba"))  # fmt: skip
    sc = _load(res / "relpose_selfcal_scaled.yaml")
    sc_joint = np.asarray(sc["joint"]["position_in_a"]) / truth_s["scale"]["mu_a"]
    table.add_row("self-calibration: joint in A (A units / mu_a)", _v(tj["position_in_a"]),
                  "n/a", _v(sc_joint))  # fmt: skip
    table.add_row("self-calibration: phi_ba", f"{truth_s['scale']['phi_ba']:.4f}", "n/a",
                  f"{sc['scale']['phi_ba']:.4f}")  # fmt: skip
    console.print(table)
    console.print(f"artifacts in {res}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
