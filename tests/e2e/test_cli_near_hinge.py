"""A near-hinge ball joint through the real CLI in every mode (issue 20, item 3): `joint
--overlap`, `relpose --self-calibrate` and a rig config each warn the same way, naming the
articulation's principal axis in each body's frame and the joint's weak direction with its
std, and record the motion in their artifact; whole and halved recordings alike; a
well-spread ball does not warn."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_runner import acscal

from acs_cli.io.joint import JointArtifact, MotionQuality
from acs_cli.io.relpose import RelposeArtifact
from acs_cli.io.rig import RigArtifact
from acs_cli.io.trajectory import write_tum
from sample_data_gen.acs_sim import NearHingePair, near_hinge_pair

N = 120
CUTS = {"whole": N, "half": N // 2}
COS_3DEG = np.cos(np.radians(3.0))


def _files(root: Path, pair: NearHingePair) -> dict[str, dict[str, Path]]:
    """Per cut: A's and B's poses in one world (``a``, ``b``) and B's in its own (``bo``)."""
    out: dict[str, dict[str, Path]] = {}
    for cut, n in CUTS.items():
        out[cut] = {}
        for key, T in (("a", pair.T_w_a), ("b", pair.T_w_b), ("bo", pair.T_wb_b)):
            out[cut][key] = root / f"{cut}_{key}.tum"
            write_tum(out[cut][key], pair.timestamps[:n], T[:n])
    return out


@pytest.fixture(scope="module")
def knee(tmp_path_factory: pytest.TempPathFactory) -> tuple[NearHingePair, Any]:
    pair = near_hinge_pair(np.random.default_rng(5), N)
    return pair, _files(tmp_path_factory.mktemp("knee"), pair)


@pytest.fixture(scope="module")
def ball(tmp_path_factory: pytest.TempPathFactory) -> tuple[NearHingePair, Any]:
    pair = near_hinge_pair(np.random.default_rng(6), N, wobble_deg=20.0)
    return pair, _files(tmp_path_factory.mktemp("ball"), pair)


def _run(mode: str, files: dict[str, Path], out: Path) -> tuple[str, Any]:
    """Run ``mode`` (overlap, relpose, rig) on one cut; its stderr and its motion records
    (body -> MotionQuality, bodies named ``a`` and ``b``) and warnings."""
    if mode == "overlap":
        res = acscal("joint", "--overlap", "--poses-a", files["a"], "--poses-b", files["b"],
                     "-o", out / "joint.yaml")  # fmt: skip
        assert res.returncode == 0, res.stderr
        art = JointArtifact.load(out / "joint.yaml")
        return res.stderr, (art.quality.motion, art.warnings)
    if mode == "relpose":
        res = acscal("relpose", "--self-calibrate", "--poses-a", files["a"], "--poses-b",
                     files["bo"], "-o", out / "relpose.yaml")  # fmt: skip
        assert res.returncode == 0, res.stderr
        rel = RelposeArtifact.load(out / "relpose.yaml")
        return res.stderr, (rel.quality.motion, rel.warnings)
    cfg = out / "rig.yaml"
    cfg.write_text(
        f"schema_version: 2\noutput: {out / 'run'}\ncameras:\n  a: {{poses: {files['a']}}}\n"
        f"  b: {{poses: {files['bo']}}}\njoints:\n  knee: {{between: [a, b], type: ball}}\n",
        encoding="utf-8",
    )
    res = acscal("run", cfg)
    assert res.returncode == 0, res.stderr
    rig = RigArtifact.load(out / "run" / "rig.yaml")
    return res.stderr, (rig.joints["knee"].motion, rig.warnings)


def _vec(v: np.ndarray) -> str:
    return "[" + " ".join(f"{x:+.3f}" for x in v) + "]"


@pytest.mark.parametrize("cut", list(CUTS))
@pytest.mark.parametrize("mode", ["overlap", "relpose", "rig"])
def test_near_hinge_warns_with_axes_and_weak_direction(
    knee: tuple[NearHingePair, Any], tmp_path: Path, mode: str, cut: str
) -> None:
    pair, files = knee
    stderr, (motion, warnings) = _run(mode, files[cut], tmp_path)
    assert set(motion) == {"a", "b"}
    a: MotionQuality = motion["a"]
    b: MotionQuality = motion["b"]
    assert a.near_hinge and b.near_hinge
    assert abs(a.dominant_axis @ pair.axis_in_a) > COS_3DEG
    assert abs(b.dominant_axis @ pair.axis_in_b) > COS_3DEG
    assert abs(a.weak_direction @ pair.axis_in_a) > 0.99  # the centre is weak along the axis
    assert abs(b.weak_direction @ pair.axis_in_b) > 0.99
    (text,) = [w for w in warnings if "near-hinge motion" in w]
    who, A, B = ("joint knee", "a", "b") if mode == "rig" else ("the joint", "A", "B")
    for part in (
        f"{who}: near-hinge motion (rotation ratio",
        f"about the axis {_vec(a.dominant_axis)} in {A}'s frame and "
        f"{_vec(b.dominant_axis)} in {B}'s frame",
        f"weakly determined along {_vec(a.weak_direction)} in {A} (std {a.weak_std:.3g} m) "
        f"and {_vec(b.weak_direction)} in {B} (std {b.weak_std:.3g} m)",
    ):
        assert part in text, (part, text)
    assert " ".join(text.split()) in " ".join(stderr.split())  # "warning: [rig: ]..."


@pytest.mark.parametrize("mode", ["overlap", "relpose", "rig"])
def test_well_spread_ball_does_not_warn(
    ball: tuple[NearHingePair, Any], tmp_path: Path, mode: str
) -> None:
    _pair, files = ball
    stderr, (motion, warnings) = _run(mode, files["whole"], tmp_path)
    assert set(motion) == {"a", "b"} and not any(m.near_hinge for m in motion.values())
    assert not any("near-hinge" in w for w in warnings) and "near-hinge" not in stderr
