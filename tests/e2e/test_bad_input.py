"""Bad input, table-driven, through the real ``acscal`` console script.

Every case must end with exit code 2 and exactly one line on stderr,
``acscal: error: <file>[:<line>]: <message>``, naming the offending file (and line, for
text pose files), without a traceback or a rich box; and it must write nothing: an artifact
already at the output path stays byte-identical (same inode, same mtime), no other file
(``*.tmp`` included) appears beside it, and a fresh output path stays absent.

The cases run concurrently (two at a time) in a module fixture; each test checks one.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cli_runner
import cv2
import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from acs_cli.io.detections import cache_path_for
from acs_cli.io.trajectory import write_kitti, write_tum
from acs_cli.stages.export import run_export
from acs_cli.stages.intrinsics import IntrinsicsConfig, run_intrinsics
from acs_cli.stages.joint import JointConfig, run_joint
from acs_cli.stages.poses import PosesConfig, run_poses
from acs_cli.stages.relpose import RelposeConfig, run_relpose
from sample_data_gen import acs_sim

SIZE = (320, 240)


def acscal(*args: str | Path, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
    return cli_runner.acscal(*args, cwd=cwd, timeout=120)


# ----------------------------------------------------------------------------- synthetic data


def draw_views(
    folder: Path,
    n: int,
    size: tuple[int, int] = SIZE,
    board: tuple[int, int] = (9, 6),
    square: float = 0.025,
    seed: int = 0,
    ext: str = ".png",
) -> list[Path]:
    """``n`` views of a ``board`` checkerboard (inner corners) by an ideal pinhole camera.

    The board (with a white border) is warped by the homography of a random pose, 10-35
    degrees off the optical axis, then blurred and given sensor noise.
    """
    cols, rows = board
    w, h = size
    sq = 24  # texture pixels a square
    tex = np.full(((rows + 5) * sq, (cols + 5) * sq), 255, np.uint8)
    for r in range(rows + 1):
        for c in range(cols + 1):
            if (r + c) % 2 == 0:
                tex[(r + 2) * sq : (r + 3) * sq, (c + 2) * sq : (c + 3) * sq] = 0
    f = 0.95 * w
    K = np.array([[f, 0, w / 2 - 0.5], [0, f, h / 2 - 0.5], [0, 0, 1.0]])
    A = np.array([[square / sq, 0, -3 * square], [0, square / sq, -3 * square], [0, 0, 1.0]])
    centre = np.array([(cols - 1) * square / 2, (rows - 1) * square / 2, 0.0])
    rng = np.random.default_rng(seed)
    dist = (cols + 1) * square * f / w
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n):
        axis = rng.normal(size=3) * [1.0, 1.0, 0.3]
        angle = np.radians(rng.uniform(10, 35))
        R = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()
        d = dist * rng.uniform(1.5, 1.9)
        t = np.array([rng.uniform(-0.1, 0.1) * d, rng.uniform(-0.1, 0.1) * d, d]) - R @ centre
        H = K @ np.column_stack([R[:, 0], R[:, 1], t]) @ A
        img = cv2.warpPerspective(tex, H, (w, h), flags=cv2.INTER_AREA, borderValue=150)
        img = cv2.GaussianBlur(img, (0, 0), 0.6)
        img = np.clip(img + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8)
        path = folder / f"img_{i:04d}{ext}"
        assert cv2.imwrite(str(path), img)
        paths.append(path)
    return paths


@dataclass(frozen=True)
class Workspace:
    """Good inputs and artifacts, built once for the module (in process, for speed)."""

    root: Path
    images: Path  # 10 good 320x240 PNG views of a 9x6 board
    intrinsics: Path
    poses: Path
    fixed_a: Path
    fixed_b: Path
    general_a: Path
    general_b: Path
    joint: Path
    relpose: Path
    export: Path


def _build_workspace(root: Path) -> Workspace:
    images = root / "images"
    draw_views(images, 10)
    intr = root / "cam" / "intrinsics.yaml"
    run_intrinsics(images, intr, IntrinsicsConfig(workers=1))
    poses = root / "cam" / "poses.npz"
    run_poses(images, intr, poses, PosesConfig(workers=1))
    rng = np.random.default_rng(4)
    rig = acs_sim.make_rig(rng)
    fixed = acs_sim.fixed_joint_sequence(rng, rig, 20)
    general = acs_sim.general_sequence(rng, rig, 20)
    paths = {}
    for name, seq in (("fixed", fixed), ("general", general)):
        for cam, T in (("a", seq.T_wa_a), ("b", seq.T_wb_b)):
            paths[f"{name}_{cam}"] = root / "traj" / f"{name}_{cam}.tum"
            write_tum(
                paths[f"{name}_{cam}"], seq.timestamps, acs_sim.add_pose_noise(rng, T, 0.2, 0.002)
            )
    joint = root / "joint.yaml"
    run_joint(paths["fixed_a"], paths["fixed_b"], joint, JointConfig())
    relpose = root / "relpose.yaml"
    run_relpose(paths["general_a"], paths["general_b"], joint, relpose, RelposeConfig())
    export = root / "relpose_cv.yaml"
    run_export(relpose, export, "opencv")
    return Workspace(
        root, images, intr, poses, paths["fixed_a"], paths["fixed_b"], paths["general_a"],
        paths["general_b"], joint, relpose, export,
    )  # fmt: skip


# ----------------------------------------------------------------------------- the cases


@dataclass
class Spec:
    """One bad invocation: its arguments, what the message must name, and its output."""

    args: list[str | Path]
    names: Path | str  # the offending file, as the message must name it
    output: Path | None  # the output path, checked untouched (None: no output to check)
    line: int | None = None  # the line the message must name (text pose files)
    good: Path | None = None  # a good artifact placed at the output path first
    contains: str = ""  # a phrase the message must hold
    also: list[Path] = field(default_factory=list)  # inputs that must stay untouched


Builder = Callable[[Workspace, Path], Spec]
CASES: dict[str, Builder] = {}
#: Cases also run with no artifact at the output path (one per command at least).
FRESH = (
    "intrinsics-no-board",
    "poses-wrong-stage",
    "joint-tum-nan",
    "relpose-no-common-timestamps",
    "export-missing-key",
    "run-empty-images",
)


def case(name: str) -> Callable[[Builder], Builder]:
    def register(fn: Builder) -> Builder:
        assert name not in CASES
        CASES[name] = fn
        return fn

    return register


def _copy_images(ws: Workspace, dest: Path, n: int = 10) -> Path:
    dest.mkdir(parents=True)
    for p in sorted(ws.images.iterdir())[:n]:
        shutil.copy(p, dest / p.name)
    return dest


def _tum_lines(ws: Workspace) -> list[str]:
    return [s for s in ws.fixed_a.read_text().splitlines() if s and not s.startswith("#")]


def _write_lines(path: Path, lines: list[str]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def _yaml_edit(src: Path, dest: Path, edit: Callable[[dict], object]) -> Path:
    doc = yaml.safe_load(src.read_text())
    edit(doc)
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(yaml.safe_dump(doc, sort_keys=False))
    return dest


def _truncated(src: Path, dest: Path, fraction: float = 0.5) -> Path:
    data = src.read_bytes()
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_bytes(data[: int(len(data) * fraction)])
    return dest


def _not_writable(d: Path, name: str) -> Path:
    """An output path whose parent is a regular file (unwritable even for root)."""
    blocker = d / "blocker"
    blocker.write_text("a regular file, not a folder\n")
    return blocker / "sub" / name


# -- intrinsics


def _intr(ws: Workspace, d: Path, images: Path, *extra: str, names: Path | str = "") -> Spec:
    out = d / "out" / "intrinsics.yaml"
    args: list[str | Path] = ["intrinsics", images, "--board", "9x6", "--square", "0.025"]
    return Spec([*args, *extra, "-o", out], names or images, out, good=ws.intrinsics)


@case("intrinsics-missing-folder")
def _(ws: Workspace, d: Path) -> Spec:
    return _intr(ws, d, d / "nope")


@case("intrinsics-empty-folder")
def _(ws: Workspace, d: Path) -> Spec:
    (d / "imgs").mkdir()
    return _intr(ws, d, d / "imgs")


@case("intrinsics-folder-is-a-file")
def _(ws: Workspace, d: Path) -> Spec:
    (d / "imgs.png").write_bytes(ws.images.joinpath("img_0000.png").read_bytes())
    return _intr(ws, d, d / "imgs.png")


@case("intrinsics-no-images")
def _(ws: Workspace, d: Path) -> Spec:
    (d / "imgs").mkdir()
    (d / "imgs" / "notes.txt").write_text("no images here\n")
    (d / "imgs" / "poses.npz").write_bytes(ws.poses.read_bytes())
    return _intr(ws, d, d / "imgs")


@case("intrinsics-corrupt-png")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = _copy_images(ws, d / "imgs", 4)
    bad = imgs / "img_0002.png"
    bad.write_bytes(np.random.default_rng(1).bytes(3000))
    return _intr(ws, d, imgs, names=bad)


@case("intrinsics-truncated-png")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = _copy_images(ws, d / "imgs", 4)
    bad = _truncated(imgs / "img_0001.png", imgs / "img_0001.png", 0.6)
    return _intr(ws, d, imgs, names=bad)


@case("intrinsics-truncated-jpeg")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = _copy_images(ws, d / "imgs", 4)
    img = cv2.imread(str(imgs / "img_0003.png"), cv2.IMREAD_GRAYSCALE)
    ok, jpg = cv2.imencode(".jpg", img)
    assert ok
    bad = imgs / "img_0003.jpg"
    bad.write_bytes(jpg.tobytes()[: len(jpg) // 2])
    (imgs / "img_0003.png").unlink()
    return _intr(ws, d, imgs, names=bad)


@case("intrinsics-empty-image-file")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = _copy_images(ws, d / "imgs", 4)
    (imgs / "img_0009.png").write_bytes(b"")
    return _intr(ws, d, imgs, names=imgs / "img_0009.png")


@case("intrinsics-different-sizes")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = _copy_images(ws, d / "imgs", 6)
    draw_views(d / "big", 1, size=(400, 300), seed=5)
    odd = imgs / "img_0003.png"
    shutil.copy(d / "big" / "img_0000.png", odd)
    spec = _intr(ws, d, imgs, names=odd)
    spec.contains = "differs"
    return spec


@case("intrinsics-no-board")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = d / "imgs"
    imgs.mkdir()
    rng = np.random.default_rng(2)
    for i in range(3):
        noise = cv2.GaussianBlur(rng.uniform(0, 255, SIZE[::-1]).astype(np.uint8), (0, 0), 3)
        cv2.imwrite(str(imgs / f"blank_{i}.png"), noise)
    spec = _intr(ws, d, imgs)
    spec.contains = "no 9x6 board found in any of 3 images"
    return spec


@case("intrinsics-wrong-board")
def _(ws: Workspace, d: Path) -> Spec:
    out = d / "out" / "intrinsics.yaml"
    args = ["intrinsics", ws.images, "--board", "8x5", "-o", out]
    return Spec(args, ws.images, out, good=ws.intrinsics, contains="no 8x5 board found")


@case("intrinsics-output-parent-is-a-file")
def _(ws: Workspace, d: Path) -> Spec:
    out = _not_writable(d, "intrinsics.yaml")
    return Spec(["intrinsics", ws.images, "-o", out], d / "blocker", out, contains="cannot")


@case("intrinsics-output-in-proc")
def _(ws: Workspace, d: Path) -> Spec:
    out = Path("/proc/acscal-no-such-dir/intrinsics.yaml")
    return Spec(["intrinsics", ws.images, "-o", out], out.parent, out, contains="cannot")


@case("intrinsics-output-is-an-input-image")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = _copy_images(ws, d / "imgs", 10)
    victim = imgs / "img_0004.png"
    spec = Spec(["intrinsics", imgs, "-o", victim], victim, victim, contains="overwrite")
    spec.also = [victim]
    return spec


@case("intrinsics-output-is-the-folder")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = _copy_images(ws, d / "imgs", 10)
    return Spec(["intrinsics", imgs, "-o", imgs], imgs, None)


# -- poses


def _poses(ws: Workspace, d: Path, intr: Path, images: Path | None = None) -> Spec:
    out = d / "out" / "poses.npz"
    args: list[str | Path] = ["poses", images or ws.images, "--intrinsics", intr, "-o", out]
    return Spec(args, intr, out, good=ws.poses)


@case("poses-wrong-stage")
def _(ws: Workspace, d: Path) -> Spec:
    spec = _poses(ws, d, ws.joint)
    spec.contains = "expected acscal/intrinsics"
    return spec


@case("poses-intrinsics-is-a-trajectory")
def _(ws: Workspace, d: Path) -> Spec:
    return _poses(ws, d, ws.fixed_a)


@case("poses-intrinsics-missing-key")
def _(ws: Workspace, d: Path) -> Spec:
    bad = _yaml_edit(
        ws.intrinsics, d / "in" / "intrinsics.yaml", lambda doc: doc.pop("camera_matrix")
    )
    spec = _poses(ws, d, bad)
    spec.contains = "camera_matrix"
    return spec


@case("poses-intrinsics-newer-schema")
def _(ws: Workspace, d: Path) -> Spec:
    bad = _yaml_edit(
        ws.intrinsics, d / "in" / "intrinsics.yaml", lambda doc: doc.update(schema_version=99)
    )
    spec = _poses(ws, d, bad)
    spec.contains = "newer acscal"
    return spec


@case("poses-intrinsics-bad-matrix")
def _(ws: Workspace, d: Path) -> Spec:
    bad = _yaml_edit(
        ws.intrinsics,
        d / "in" / "intrinsics.yaml",
        lambda doc: doc.update(camera_matrix=[[1, 0], [0, 1]]),
    )
    return _poses(ws, d, bad)


@case("poses-intrinsics-truncated-yaml")
def _(ws: Workspace, d: Path) -> Spec:
    text = ws.intrinsics.read_text()
    cut = text.index("camera_matrix:")
    bad = d / "in" / "intrinsics.yaml"
    bad.parent.mkdir()
    bad.write_text(text[:cut] + "camera_matrix: [[500.0, 0, 160\n")
    spec = _poses(ws, d, bad)
    spec.line = text[:cut].count("\n") + 2  # the parser stops at the end of the file
    return spec


@case("poses-images-of-another-size")
def _(ws: Workspace, d: Path) -> Spec:
    draw_views(d / "imgs", 3, size=(400, 300), seed=7)
    spec = _poses(ws, d, ws.intrinsics, d / "imgs")
    spec.names = d / "imgs"
    spec.contains = "calibrated at 320x240"
    return spec


@case("poses-wrong-board")
def _(ws: Workspace, d: Path) -> Spec:
    spec = _poses(ws, d, ws.intrinsics)
    spec.args[1:1] = ["--board", "7x4"]
    spec.names = ws.images
    spec.contains = "no 7x4 board found"
    return spec


@case("poses-output-is-the-intrinsics")
def _(ws: Workspace, d: Path) -> Spec:
    intr = d / "in" / "intrinsics.yaml"
    intr.parent.mkdir()
    shutil.copy(ws.intrinsics, intr)
    args = ["poses", ws.images, "--intrinsics", intr, "-o", intr]
    return Spec(args, intr, intr, contains="overwrite", also=[intr])


@case("poses-tum-is-an-input-image")
def _(ws: Workspace, d: Path) -> Spec:
    imgs = _copy_images(ws, d / "imgs", 10)
    victim = imgs / "img_0007.png"
    spec = _poses(ws, d, ws.intrinsics, imgs)
    spec.args += ["--tum", victim]
    spec.names, spec.contains, spec.also = victim, "overwrite", [victim]
    return spec


@case("poses-tum-unwritable")
def _(ws: Workspace, d: Path) -> Spec:
    """The second output cannot be written: the first (a good NPZ there) must survive."""
    spec = _poses(ws, d, ws.intrinsics)
    tum = _not_writable(d, "poses.tum")
    spec.args += ["--tum", tum]
    spec.names, spec.contains = d / "blocker", "cannot"
    return spec


@case("poses-tum-is-the-output")
def _(ws: Workspace, d: Path) -> Spec:
    out = d / "out" / "poses.npz"
    args = ["poses", ws.images, "--intrinsics", ws.intrinsics, "-o", out, "--tum", out]
    return Spec(args, out, out, good=ws.poses)


# -- joint (and the pose-file cases)


def _joint(
    ws: Workspace, d: Path, poses_a: Path, line: int | None = None, contains: str = ""
) -> Spec:
    out = d / "out" / "joint.yaml"
    args = ["joint", "--fixed-joint", "--poses-a", poses_a, "--poses-b", ws.fixed_b, "-o", out]
    return Spec(args, poses_a, out, line=line, good=ws.joint, contains=contains)


@case("joint-tum-empty")
def _(ws: Workspace, d: Path) -> Spec:
    return _joint(
        ws, d, _write_lines(d / "in" / "a.tum", ["# only a comment"]), contains="no poses"
    )


@case("joint-tum-wrong-column-count")
def _(ws: Workspace, d: Path) -> Spec:
    lines = _tum_lines(ws)
    lines[4] = " ".join(lines[4].split()[:7])
    return _joint(ws, d, _write_lines(d / "in" / "a.tum", lines), line=5, contains="expected 8")


@case("joint-tum-nan")
def _(ws: Workspace, d: Path) -> Spec:
    lines = _tum_lines(ws)
    parts = lines[6].split()
    parts[2] = "nan"
    lines[6] = " ".join(parts)
    return _joint(ws, d, _write_lines(d / "in" / "a.tum", lines), line=7, contains="NaN")


@case("joint-tum-inf")
def _(ws: Workspace, d: Path) -> Spec:
    lines = ["# timestamp tx ty tz qx qy qz qw", *_tum_lines(ws)]
    parts = lines[3].split()
    parts[1] = "-inf"
    lines[3] = " ".join(parts)
    return _joint(ws, d, _write_lines(d / "in" / "a.tum", lines), line=4, contains="inf")


@case("joint-tum-non-unit-quaternion")
def _(ws: Workspace, d: Path) -> Spec:
    lines = _tum_lines(ws)
    parts = lines[8].split()
    parts[4:8] = [str(1.2 * float(v)) for v in parts[4:8]]
    lines[8] = " ".join(parts)
    return _joint(ws, d, _write_lines(d / "in" / "a.tum", lines), line=9, contains="quaternion")


@case("joint-tum-duplicated-timestamp")
def _(ws: Workspace, d: Path) -> Spec:
    lines = _tum_lines(ws)
    lines.insert(5, lines[4])
    return _joint(ws, d, _write_lines(d / "in" / "a.tum", lines), line=6, contains="repeats")


@case("joint-tum-decreasing-timestamp")
def _(ws: Workspace, d: Path) -> Spec:
    lines = _tum_lines(ws)
    lines[10], lines[11] = lines[11], lines[10]
    return _joint(ws, d, _write_lines(d / "in" / "a.tum", lines), line=12, contains="before")


@case("joint-kitti-non-orthonormal")
def _(ws: Workspace, d: Path) -> Spec:
    rng = np.random.default_rng(5)
    T = acs_sim.fixed_joint_sequence(rng, acs_sim.make_rig(rng), 8).T_wa_a
    path = d / "in" / "a.txt"
    path.parent.mkdir()
    write_kitti(path, T)
    lines = path.read_text().splitlines()
    parts = lines[3].split()
    parts[0] = str(float(parts[0]) + 0.01)
    lines[3] = " ".join(parts)
    spec = _joint(ws, d, _write_lines(path, lines), line=4, contains="orthonormal")
    spec.args[spec.args.index("--poses-b") + 1] = path  # two KITTI files: paired by index
    return spec


@case("joint-npz-truncated")
def _(ws: Workspace, d: Path) -> Spec:
    return _joint(ws, d, _truncated(ws.poses, d / "in" / "a.npz"), contains="NPZ")


@case("joint-npz-nan")
def _(ws: Workspace, d: Path) -> Spec:
    with np.load(ws.poses) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["T_world_cam"][2, 0, 3] = np.nan
    path = d / "in" / "a.npz"
    path.parent.mkdir()
    np.savez(path, **arrays)
    return _joint(ws, d, path, contains="NaN")


@case("joint-npz-wrong-stage")
def _(ws: Workspace, d: Path) -> Spec:
    cache = cache_path_for(ws.intrinsics)
    return _joint(ws, d, cache, contains="expected acscal/poses")


@case("joint-poses-is-an-artifact")
def _(ws: Workspace, d: Path) -> Spec:
    return _joint(ws, d, ws.intrinsics, contains="acscal/intrinsics")


@case("joint-no-common-timestamps")
def _(ws: Workspace, d: Path) -> Spec:
    lines = _tum_lines(ws)
    shifted = [" ".join([str(float(s.split()[0]) + 1000.0), *s.split()[1:]]) for s in lines]
    b = _write_lines(d / "in" / "b.tum", shifted)
    out = d / "out" / "joint.yaml"
    args = ["joint", "--overlap", "--poses-a", ws.general_a, "--poses-b", b, "-o", out]
    return Spec(args, b, out, good=ws.joint, contains="no common timestamps")


@case("joint-output-is-an-input")
def _(ws: Workspace, d: Path) -> Spec:
    a = d / "in" / "a.tum"
    a.parent.mkdir()
    shutil.copy(ws.fixed_a, a)
    args = ["joint", "--fixed-joint", "--poses-a", a, "--poses-b", ws.fixed_b, "-o", a]
    return Spec(args, a, a, contains="overwrite", also=[a])


@case("joint-output-parent-is-a-file")
def _(ws: Workspace, d: Path) -> Spec:
    out = _not_writable(d, "joint.yaml")
    args = ["joint", "--fixed-joint", "--poses-a", ws.fixed_a, "--poses-b", ws.fixed_b, "-o", out]
    return Spec(args, d / "blocker", out, contains="cannot")


# -- relpose


def _relpose(ws: Workspace, d: Path, joint: Path, contains: str = "") -> Spec:
    out = d / "out" / "relpose.yaml"
    args = [
        "relpose", "--joint", joint, "--poses-a", ws.general_a, "--poses-b", ws.general_b,
        "-o", out,
    ]  # fmt: skip
    return Spec(args, joint, out, good=ws.relpose, contains=contains)


@case("relpose-joint-missing-key")
def _(ws: Workspace, d: Path) -> Spec:
    bad = _yaml_edit(
        ws.joint, d / "in" / "joint.yaml", lambda doc: doc["joint"].pop("position_in_a")
    )
    return _relpose(ws, d, bad, contains="position_in_a")


@case("relpose-joint-newer-schema")
def _(ws: Workspace, d: Path) -> Spec:
    bad = _yaml_edit(ws.joint, d / "in" / "joint.yaml", lambda doc: doc.update(schema_version=2))
    return _relpose(ws, d, bad, contains="newer acscal")


@case("relpose-joint-wrong-stage")
def _(ws: Workspace, d: Path) -> Spec:
    return _relpose(ws, d, ws.intrinsics, contains="expected acscal/joint")


@case("relpose-joint-truncated")
def _(ws: Workspace, d: Path) -> Spec:
    text = ws.joint.read_text()
    cut = text.index("position_in_a:")
    bad = d / "in" / "joint.yaml"
    bad.parent.mkdir()
    bad.write_text(text[: cut + len("position_in_a: [0.1, ")])
    return _relpose(ws, d, bad, contains="YAML")


@case("relpose-no-common-timestamps")
def _(ws: Workspace, d: Path) -> Spec:
    lines = [s for s in ws.general_b.read_text().splitlines() if s and not s.startswith("#")]
    shifted = [" ".join([str(float(s.split()[0]) - 500.0), *s.split()[1:]]) for s in lines]
    b = _write_lines(d / "in" / "b.tum", shifted)
    spec = _relpose(ws, d, ws.joint, contains="no common timestamps")
    spec.args[spec.args.index("--poses-b") + 1] = b
    spec.names = b
    return spec


@case("relpose-output-is-the-joint")
def _(ws: Workspace, d: Path) -> Spec:
    joint = d / "in" / "joint.yaml"
    joint.parent.mkdir()
    shutil.copy(ws.joint, joint)
    spec = _relpose(ws, d, joint, contains="overwrite")
    spec.args[-1] = joint
    spec.output, spec.good, spec.also = joint, None, [joint]
    return spec


# -- export


def _export(ws: Workspace, d: Path, rel: Path, fmt: str = "opencv", contains: str = "") -> Spec:
    out = d / "out" / "relpose_cv.yaml"
    args = ["export", rel, "--format", fmt, "-o", out]
    return Spec(args, rel, out, good=ws.export, contains=contains)


@case("export-wrong-stage")
def _(ws: Workspace, d: Path) -> Spec:
    return _export(ws, d, ws.joint, contains="expected acscal/relpose")


@case("export-missing-key")
def _(ws: Workspace, d: Path) -> Spec:
    bad = _yaml_edit(
        ws.relpose, d / "in" / "rel.yaml", lambda doc: doc["relative_pose"].pop("T_b_a")
    )
    return _export(ws, d, bad, contains="relative_pose.T_b_a")


@case("export-newer-schema")
def _(ws: Workspace, d: Path) -> Spec:
    bad = _yaml_edit(ws.relpose, d / "in" / "rel.yaml", lambda doc: doc.update(schema_version=3))
    return _export(ws, d, bad, "kalibr", contains="newer acscal")


@case("export-not-a-rigid-transform")
def _(ws: Workspace, d: Path) -> Spec:
    def scale(doc: dict) -> None:
        doc["relative_pose"]["T_b_a"][0][0] *= 1.5

    bad = _yaml_edit(ws.relpose, d / "in" / "rel.yaml", scale)
    return _export(ws, d, bad, "kalibr")


@case("export-truncated")
def _(ws: Workspace, d: Path) -> Spec:
    return _export(ws, d, _truncated(ws.relpose, d / "in" / "rel.yaml", 0.0), contains="mapping")


@case("export-output-is-the-input")
def _(ws: Workspace, d: Path) -> Spec:
    rel = d / "in" / "rel.yaml"
    rel.parent.mkdir()
    shutil.copy(ws.relpose, rel)
    return Spec(["export", rel, "-o", rel], rel, rel, contains="overwrite", also=[rel])


@case("export-output-parent-is-a-file")
def _(ws: Workspace, d: Path) -> Spec:
    out = _not_writable(d, "chain.yaml")
    return Spec(["export", ws.relpose, "-o", out], d / "blocker", out, contains="cannot")


# -- run

RUN_CONFIG = """\
schema: acscal/run-config
schema_version: 1
output: run
board: {{cols: 9, rows: 6, square: 0.025}}
cameras:
  a: {{images: {images}}}
intrinsics: {{from: joint}}
joint: {{scenario: fixed_joint}}
"""


def _run(ws: Workspace, d: Path, text: str | None = None, images: Path | None = None) -> Spec:
    config = d / "run.yaml"
    config.write_text(text if text is not None else RUN_CONFIG.format(images=images or ws.images))
    out = d / "run" / "joint.yaml"
    return Spec(["run", config], config, out, good=ws.joint)


@case("run-missing-config")
def _(ws: Workspace, d: Path) -> Spec:
    spec = _run(ws, d)
    spec.args[1] = spec.names = d / "nope.yaml"
    return spec


@case("run-missing-key")
def _(ws: Workspace, d: Path) -> Spec:
    text = RUN_CONFIG.format(images=ws.images).replace(
        "board: {cols: 9, rows: 6, square: 0.025}\n", ""
    )
    spec = _run(ws, d, text)
    spec.contains = "'board'"
    return spec


@case("run-newer-schema")
def _(ws: Workspace, d: Path) -> Spec:
    spec = _run(
        ws, d, RUN_CONFIG.format(images=ws.images).replace("schema_version: 1", "schema_version: 2")
    )
    spec.contains = "newer"
    return spec


@case("run-yaml-syntax-error")
def _(ws: Workspace, d: Path) -> Spec:
    spec = _run(
        ws, d, RUN_CONFIG.format(images=ws.images).replace("joint: {scenario", "joint: [scenario")
    )
    spec.line = 8
    return spec


@case("run-config-is-an-artifact")
def _(ws: Workspace, d: Path) -> Spec:
    config = d / "joint.yaml"
    shutil.copy(ws.joint, config)
    return Spec(["run", config], config, None, contains="acscal/run-config")


@case("run-empty-images")
def _(ws: Workspace, d: Path) -> Spec:
    (d / "imgs").mkdir()
    spec = _run(ws, d, images=d / "imgs")
    spec.names = d / "imgs"
    spec.contains = "empty"
    return spec


@case("run-intrinsics-from-wrong-stage")
def _(ws: Workspace, d: Path) -> Spec:
    text = RUN_CONFIG.format(images=ws.images).replace(
        "intrinsics: {from: joint}", f"intrinsics_from: {{a: {ws.joint}}}"
    )
    spec = _run(ws, d, text)
    spec.names = ws.joint
    spec.contains = "expected acscal/intrinsics"
    return spec


@case("run-output-is-the-config")
def _(ws: Workspace, d: Path) -> Spec:
    text = RUN_CONFIG.format(images=ws.images).replace("output: run", "output: run.yaml")
    spec = _run(ws, d, text)
    spec.contains = "cannot"
    spec.output, spec.good, spec.also = None, None, [d / "run.yaml"]
    return spec


# ----------------------------------------------------------------------------- running them


@dataclass
class Outcome:
    spec: Spec
    result: subprocess.CompletedProcess[str]
    before: dict[Path, tuple[bytes, int, int]]  # untouched files: bytes, inode, mtime_ns
    listing_before: set[Path]
    fresh: bool
    seconds: float


def _snapshot(paths: list[Path]) -> dict[Path, tuple[bytes, int, int]]:
    out = {}
    for p in paths:
        st = p.stat()
        out[p] = (p.read_bytes(), st.st_ino, st.st_mtime_ns)
    return out


def _listing(folder: Path | None) -> set[Path]:
    if folder is None or not folder.is_dir():
        return set()
    return set(folder.iterdir())


def _run_case(ws: Workspace, root: Path, name: str, fresh: bool) -> Outcome:
    d = root / (name + ("-fresh" if fresh else ""))
    d.mkdir(parents=True)
    spec = CASES[name](ws, d)
    if spec.output is not None and spec.good is not None and not fresh:
        spec.output.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(spec.good, spec.output)
    keep = [p for p in [*spec.also, spec.output] if p is not None and p.is_file()]
    before = _snapshot(list(dict.fromkeys(keep)))
    listing = _listing(None if spec.output is None else spec.output.parent)
    t0 = time.perf_counter()
    result = acscal(*spec.args, cwd=d)
    return Outcome(spec, result, before, listing, fresh, time.perf_counter() - t0)


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Outcome]:
    root = tmp_path_factory.mktemp("bad_input")
    ws = _build_workspace(root / "ws")
    jobs = [(name, False) for name in CASES] + [(name, True) for name in FRESH]
    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {
            (name + ("-fresh" if fresh else "")): pool.submit(
                _run_case, ws, root / "cases", name, fresh
            )
            for name, fresh in jobs
        }
        return {key: fut.result() for key, fut in futures.items()}


def _check(o: Outcome) -> str:
    res, spec = o.result, o.spec
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr and "╭" not in res.stderr and "│" not in res.stderr
    assert res.stderr.endswith("\n") and res.stderr.count("\n") == 1, repr(res.stderr)
    msg = res.stderr.rstrip("\n")
    assert msg.startswith("acscal: error: "), msg
    where = str(spec.names)
    if spec.line is not None:
        assert f"{where}:{spec.line}: " in msg, (msg, where, spec.line)
    else:
        assert where in msg, (msg, where)
    assert spec.contains in msg, (msg, spec.contains)
    # nothing written: kept files untouched, nothing new beside the output
    for p, (data, ino, mtime) in o.before.items():
        st = p.stat()
        assert (p.read_bytes(), st.st_ino, st.st_mtime_ns) == (data, ino, mtime), p
    if spec.output is not None:
        if spec.output not in o.before:
            assert not spec.output.exists(), spec.output
        new = _listing(spec.output.parent) - o.listing_before
        # the detections cache is finished work, kept so that a rerun resumes
        assert all(p.name.endswith(".detections.npz") for p in new), sorted(new)
    return msg


@pytest.mark.parametrize("name", sorted(CASES))
def test_bad_input(outcomes: dict[str, Outcome], name: str) -> None:
    o = outcomes[name]
    if o.spec.output is not None and o.spec.good is not None:
        assert o.spec.output in o.before  # a good artifact was there, and must survive
    print(f"{o.seconds:.1f} s: {_check(o)}")


@pytest.mark.parametrize("name", FRESH)
def test_bad_input_fresh_output(outcomes: dict[str, Outcome], name: str) -> None:
    o = outcomes[name + "-fresh"]
    assert o.spec.output is not None and not o.before
    print(_check(o))


def test_every_command_is_covered() -> None:
    commands = {name.split("-")[0] for name in CASES}
    assert commands == {"intrinsics", "poses", "joint", "relpose", "export", "run"}
    assert {name.split("-")[0] for name in FRESH} == commands


@pytest.mark.skipif(
    hasattr(os, "geteuid") and os.geteuid() == 0,
    reason="running as root: a read-only folder is still writable (the parent-is-a-file and "
    "/proc cases cover unwritable outputs)",
)
def test_read_only_output_folder(tmp_path: Path) -> None:
    a = tmp_path / "a.tum"
    rng = np.random.default_rng(1)
    rig = acs_sim.make_rig(rng)
    seq = acs_sim.fixed_joint_sequence(rng, rig, 12)
    write_tum(a, seq.timestamps, seq.T_wa_a)
    ro = tmp_path / "ro"
    ro.mkdir()
    out = ro / "joint.yaml"
    out.write_text("schema: acscal/joint\n")
    ro.chmod(0o555)
    try:
        res = acscal("joint", "--fixed-joint", "--poses-a", a, "-o", out)
        assert res.returncode == 2, res.stderr
        lines = res.stderr.splitlines()
        assert len(lines) == 1 and str(out) in lines[0] and "Traceback" not in res.stderr
        assert out.read_text() == "schema: acscal/joint\n"
        assert sorted(p.name for p in ro.iterdir()) == ["joint.yaml"]
    finally:
        ro.chmod(0o755)
