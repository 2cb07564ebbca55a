"""Draw ``docs/acs.png``: an articulated camera system (README, "What an ACS is").

Run from the repository: ``.venv/bin/python docs/acs_picture.py`` (matplotlib, Agg).
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle, FancyArrowPatch, Polygon

OUT = Path(__file__).resolve().parent / "acs.png"
BLUE, ORANGE, GREEN, GREY = "#1f77b4", "#ff7f0e", "#2ca02c", "#b0b0b0"


def _rot(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def _body(ax, start, end, color, alpha=1.0, width=16) -> None:
    ax.plot(
        [start[0], end[0]],
        [start[1], end[1]],
        color=color,
        lw=width,
        alpha=alpha,
        solid_capstyle="round",
        zorder=1,
    )


def _camera(ax, centre, look_deg, color, label=None, alpha=1.0) -> None:
    """A camera as a filled frustum (a trapezoid) looking along ``look_deg``."""
    R = _rot(look_deg)
    pts = np.array([[0.0, -0.12], [0.0, 0.12], [0.42, 0.3], [0.42, -0.3]]) @ R.T + centre
    ax.add_patch(Polygon(pts, closed=True, fc=color, ec="black", lw=1.0, alpha=alpha, zorder=3))
    if label:
        ax.text(
            centre[0],
            centre[1] - 0.55,
            label,
            ha="center",
            va="center",
            fontsize=11,
            color=color,
            weight="bold",
        )


def _arrow(ax, p, q, color, text, offset, style="-|>", ls="-") -> None:
    ax.add_patch(
        FancyArrowPatch(
            p, q, arrowstyle=style, mutation_scale=14, color=color, lw=1.6, ls=ls, zorder=4
        )
    )
    mid = (np.asarray(p) + np.asarray(q)) / 2 + offset
    ax.text(*mid, text, color=color, fontsize=11, ha="center", va="center")


def draw() -> bytes:
    fig = Figure(figsize=(8.0, 3.6))
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    joint = np.array([0.0, 0.0])
    cam_a = np.array([-2.6, -0.5])
    cam_b = np.array([2.4, -0.7])
    # camera B's body articulated about the joint (another instant), in grey
    ghost = joint + _rot(38.0) @ (cam_b - joint)
    _body(ax, joint, ghost, GREY, alpha=0.5)
    _camera(ax, ghost, 105.0, GREY, alpha=0.5)
    ax.add_patch(
        FancyArrowPatch(
            cam_b * 0.55,
            ghost * 0.55,
            connectionstyle="arc3,rad=-0.3",
            arrowstyle="<|-|>",
            mutation_scale=12,
            color=GREY,
            lw=1.2,
        )
    )
    ax.text(2.2, 0.35, "the joint bends", color="#808080", fontsize=9, ha="left")
    _body(ax, cam_a, joint, "#c6dbef")
    _body(ax, joint, cam_b, "#fdd0a2")
    _camera(ax, cam_a, 150.0, BLUE, "camera A")
    _camera(ax, cam_b, 70.0, ORANGE, "camera B")
    ax.add_patch(Circle(joint, 0.2, fc=GREEN, ec="black", lw=1.2, zorder=5))
    ax.text(0.0, 0.45, "joint O (ball joint)", ha="center", fontsize=11, color=GREEN, weight="bold")
    _arrow(ax, cam_a, joint - np.array([0.22, 0.0]), BLUE, "o_a: O in A's frame", (0.0, 0.35))
    _arrow(ax, cam_b, joint + np.array([0.22, -0.04]), ORANGE, "o_b: O in B's frame", (0.15, 0.3))
    _arrow(
        ax,
        cam_a + np.array([0.0, -0.85]),
        cam_b + np.array([0.0, -0.75]),
        "#555555",
        "T_b_a: relative pose of the cameras (changes as the joint bends)",
        (0.0, -0.3),
        ls="--",
    )
    ax.text(-1.2, -0.62, "body A", fontsize=10, color="#4a6f8f", ha="center")
    ax.text(1.1, -0.72, "body B", fontsize=10, color="#b5651d", ha="center")
    ax.set_xlim(-3.6, 3.6)
    ax.set_ylim(-2.05, 1.75)
    ax.set_aspect("equal")
    ax.axis("off")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    return buf.getvalue()


def main() -> int:
    OUT.write_bytes(draw())
    print(f"wrote {OUT} ({OUT.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
