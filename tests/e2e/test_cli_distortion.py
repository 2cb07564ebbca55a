"""Issue 11: ``acscal intrinsics --model rational`` on a lens that is nearly pinhole warns
that its distortion is degenerate (exit 0); ``--model pinhole`` on the same photographs
does not. OpenCV's sample photographs (a moderate lens, 13 views of a 9x6 board)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml
from cli_runner import acscal

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "opencv_chessboard"


@pytest.mark.skipif(not DATA.is_dir(), reason=f"OpenCV sample photographs not found at {DATA}")
def test_rational_fit_of_a_moderate_lens_is_warned(tmp_path: Path) -> None:
    imgs = tmp_path / "left"
    imgs.mkdir()
    for p in sorted(DATA.glob("left*.jpg")):
        shutil.copy(p, imgs / p.name)
    out: dict[str, tuple[str, list[str]]] = {}
    for model in ("pinhole", "rational"):
        intr = tmp_path / model / "intrinsics.yaml"
        res = acscal(
            "intrinsics", imgs, "--board", "9x6", "--square", "0.025", "--model", model, "-o", intr
        )  # fmt: skip
        assert res.returncode == 0, res.stderr
        out[model] = (" ".join(res.stderr.split()), yaml.safe_load(intr.read_text())["warnings"])
    stderr, warnings = out["rational"]
    assert "the rational distortion is degenerate" in stderr
    assert any(w.startswith("the rational distortion is degenerate (") for w in warnings)
    assert "correlated at" in stderr and "k1 = " in stderr
    stderr, warnings = out["pinhole"]
    assert "degenerate" not in stderr and not any("degenerate" in w for w in warnings)
