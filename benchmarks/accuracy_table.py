"""Markdown tables of the paper's simulation study, from ``acscal simulate``'s summary.csv.

Usage::

    .venv/bin/acscal simulate -o study --trials 100 --levels 9
    .venv/bin/python benchmarks/accuracy_table.py study/summary.csv
"""

from __future__ import annotations

import argparse
import csv
import math
from pathlib import Path

MEASURES = {
    "overlap": [("joint_err_mean", "joint error (eq. 47)", 4)],
    "fixed_joint": [
        ("joint_err_mean", "joint error (eq. 47)", 4),
        ("rms_over_crlb", "RMS / Cramer-Rao bound", 3),
    ],
    "relpose": [
        ("rot_angle_err_deg_mean", "rotation error, angle (deg)", 3),
        ("rot_err_deg_mean", "rotation error, eq. 48 (deg)", 3),
        ("trans_err_mean", "translation error (eq. 49)", 4),
        ("joint_err_mean", "joint error", 4),
    ],
    "unknown_scale": [
        ("rot_angle_err_deg_mean", "rotation error, angle (deg)", 3),
        ("trans_err_mean", "translation error (eq. 49)", 4),
        ("joint_err_mean", "joint error", 4),
        ("scale_accuracy", "scale accuracy 1 - mean|phi - phi^|/phi", 4),
    ],
}


def _fmt(value: str, digits: int) -> str:
    try:
        v = float(value)
    except ValueError:
        return value
    return "" if math.isnan(v) else f"{v:.{digits}f}"


def tables(summary: Path) -> str:
    """One Markdown table a scenario: rows = noise level, columns = measure x method."""
    with open(summary, newline="") as fh:
        rows = list(csv.DictReader(fh))
    out = []
    for scenario, measures in MEASURES.items():
        sel = [r for r in rows if r["scenario"] == scenario]
        if not sel:
            continue
        levels = sorted({int(r["level"]) for r in sel})
        head = ["noise (deg / m)"]
        for _, label, _ in measures:
            head += [f"{label}, paper", f"{label}, acscal"]
        out.append(f"### {scenario}\n")
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + "---|" * len(head))
        for lv in levels:
            by_method = {r["method"]: r for r in sel if int(r["level"]) == lv}
            any_row = next(iter(by_method.values()))
            cells = [f"{float(any_row['rot_noise_deg']):.2f} / {float(any_row['trans_noise']):.4f}"]
            for key, _, digits in measures:
                for method in ("paper", "refined"):
                    cells.append(_fmt(by_method.get(method, {}).get(key, "nan"), digits))
            out.append("| " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("summary", type=Path, help="summary.csv written by acscal simulate")
    print(tables(ap.parse_args().summary))


if __name__ == "__main__":
    main()
