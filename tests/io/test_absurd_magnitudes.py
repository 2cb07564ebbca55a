"""Numbers of absurd magnitude in a user's file are refused by its reader, naming the key.

A covariance of 1e308 overflowed in ``as_covariance3`` (a RuntimeWarning, a traceback for
the user); its siblings are every reader that multiplies, squares or inverts a number it
read: covariances, stds, transforms, scales, intrinsics, timestamps, corners and target
lengths. Each is refused with an :class:`~acs_cli.errors.InputError` before the arithmetic
(``filterwarnings = error`` makes any overflow warning a failure here), and every number of
every reader's seed file, replaced by such a value, reads or is refused cleanly.
"""

from __future__ import annotations

import copy
import io
import re
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from test_fuzz_readers import NUMBER, READERS, YAML_KINDS, _paths, _rig_kalibr, _set, seeds

from acs_cli.errors import InputError
from acs_cli.io.detections import read_detections
from acs_cli.io.intrinsics import IntrinsicsArtifact
from acs_cli.io.joint import JointArtifact
from acs_cli.io.poses import PosesArtifact
from acs_cli.io.relpose import RelposeArtifact
from acs_cli.io.rig import RigArtifact
from acs_cli.io.target import parse_target_short, read_target_yaml
from acs_cli.io.trajectory import read_trajectory
from acs_cli.io.validate import as_covariance3
from acs_cli.stages.joint import read_joint
from acs_cli.stages.relpose import load_prior

#: Values that overflow a square, a product or an inverse, or underflow to zero.
ABSURD = [1e308, -1e308, 5e-324]


def _yaml_file(tmp_path: Path, kind: str, path: tuple[Any, ...], value: Any) -> Path:
    """The seed of ``kind`` with the node at ``path`` replaced by ``value``."""
    doc = _set(copy.deepcopy(yaml.safe_load(seeds()[kind])), path, "replace", value)
    out = tmp_path / f"{kind}.yaml"
    out.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return out


def _refused(read: Callable[[Path], Any], path: Path, key: str) -> InputError:
    with pytest.raises(InputError) as info:
        read(path)
    assert key in str(info.value) and str(path) in str(info.value), info.value
    assert "\n" not in str(info.value)
    return info.value


# ----------------------------------------------------------------------------- covariances


@pytest.mark.parametrize("reader", [read_joint, JointArtifact.load, lambda p: load_prior(p, True)])
@pytest.mark.parametrize(
    ("where", "value"),
    [((0, 1), 1e308), ((1, 0), 1e308), ((0, 0), -1e308), ((2, 2), 1e308), ((1, 1), 1e25)],
)
def test_a_covariance_of_absurd_size_is_refused(
    tmp_path: Path, reader: Callable[[Path], Any], where: tuple[int, int], value: float
) -> None:
    """The case Hypothesis found: 1e308 off the diagonal overflowed the correlation."""
    path = _yaml_file(tmp_path, "joint", ("joint", "covariance_a", *where), value)
    _refused(reader, path, "'joint.covariance_a'")


def test_covariance_checks_never_overflow_or_divide_by_zero() -> None:
    """Tiny variances beside large entries, subnormal ones, and zeros on the diagonal."""
    for bad in (
        [[1e-300, 1e10, 0.0], [1e10, 1e-300, 0.0], [0.0, 0.0, 1e-300]],  # correlation 1e310
        [[5e-324, 1e-300, 0.0], [1e-300, 0.0, 0.0], [0.0, 0.0, 0.0]],
        [[1.0, 0.0, 0.0], [0.0, -1e20, 0.0], [0.0, 0.0, 1.0]],
    ):
        with pytest.raises(InputError, match="'c' must be a positive semi-definite"):
            as_covariance3(bad, "c", "f.yaml")
    for good in (
        np.diag([1e20, 1.0, 0.0]),
        np.diag([5e-324, 0.0, 0.0]),
        np.diag([1e-300, 1e-300, 1e-300]),
        [[1e20, 1e19, 0.0], [1e19, 1e20, 0.0], [0.0, 0.0, 1e-30]],
    ):
        np.testing.assert_array_equal(as_covariance3(good, "c", None), good)
    with pytest.raises(InputError, match=r"'c' holds 1e\+21, beyond the 1e\+20"):
        as_covariance3(np.diag([1e21, 1.0, 1.0]), "c", None)


# ----------------------------------------------------------------------------- transforms, scales


@pytest.mark.parametrize(
    ("kind", "path", "value", "key"),
    [
        ("relpose", ("relative_pose", "T_b_a", 0, 3), 1e300, "'relative_pose.T_b_a'"),
        ("relpose", ("relative_pose", "T_b_a", 2, 3), -1e11, "'relative_pose.T_b_a'"),
        ("relpose", ("scale", "phi_ba"), 1e-300, "'scale.phi_ba'"),
        ("relpose", ("scale", "phi_ba"), 1e300, "'scale.phi_ba'"),
        ("relpose", ("scale", "mu_a"), 5e-324, "'scale.mu_a'"),
        ("relpose", ("relative_pose", "T_b_a_covariance"), [[1e300] * 6] * 6, "T_b_a_covariance"),
        ("relpose", ("joint", "position_in_b_std"), [1e300, 0, 0], "'joint.position_in_b_std'"),
        ("rig", ("cameras", "b", "T_cam_ref", 1, 3), 1e300, "'cameras.b.T_cam_ref'"),
        ("rig", ("cameras", "c", "T_ref_world", 0, 3), -1e300, "'cameras.c.T_ref_world'"),
        ("rig", ("cameras", "c", "scale"), 1e-200, "'cameras.c.scale'"),
        ("rig", ("joints", "bc", "position_in", "c", 2), 1e300, "'joints.bc.position_in.c'"),
        ("intrinsics", ("camera_matrix", 0, 0), 1e300, "'camera_matrix'"),
        ("intrinsics", ("camera_matrix", 1, 2), -1e300, "'camera_matrix'"),
        ("intrinsics", ("distortion", 0), 1e300, "'distortion'"),
    ],
)
def test_yaml_artifacts_refuse_absurd_numbers(
    tmp_path: Path, kind: str, path: tuple[Any, ...], value: Any, key: str
) -> None:
    load = {"relpose": RelposeArtifact.load, "rig": RigArtifact.load}
    if kind == "relpose" and path[0] == "relative_pose" and len(path) == 2:
        doc = yaml.safe_load(seeds()[kind])
        doc["relative_pose"]["T_b_a_covariance"] = value
        file = tmp_path / "relpose.yaml"
        file.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    else:
        file = _yaml_file(tmp_path, kind, path, value)
    _refused(load.get(kind, IntrinsicsArtifact.load), file, key)


# ----------------------------------------------------------------------------- other formats


def test_tum_timestamps_in_nanoseconds_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "a.tum"
    path.write_text(
        "1403636579763555584 0 0 0 0 0 0 1\n1403636579813555456 0.1 0 0 0 0 0 1\n",
        encoding="utf-8",
    )
    err = _refused(partial(read_trajectory, fmt="tum"), path, "'timestamps'")
    assert "wrong unit" in str(err)


def test_poses_npz_with_absurd_corners_or_board_points_is_refused(tmp_path: Path) -> None:
    with np.load(io.BytesIO(seeds()["npz"]), allow_pickle=False) as z:
        arrays = {k: np.asarray(z[k]) for k in z.files}
    for key, value in (("corners", 1e300), ("board_points", -1e200)):
        bad = dict(arrays)
        bad[key] = arrays[key].copy()
        bad[key].flat[3] = value
        path = tmp_path / f"{key}.npz"
        np.savez(path, **bad)  # type: ignore[arg-type]
        _refused(PosesArtifact.load, path, f"'{key}'")


def test_a_detections_cache_entry_with_absurd_corners_is_dropped(tmp_path: Path) -> None:
    with np.load(io.BytesIO(seeds()["detections"]), allow_pickle=False) as z:
        arrays = {k: np.asarray(z[k]) for k in z.files}
    arrays["corners"] = arrays["corners"].copy()
    arrays["corners"][0, 5, 1] = 1e300
    path = tmp_path / "x.detections.npz"
    np.savez(path, **arrays)  # type: ignore[arg-type]
    got = read_detections(path)  # a bad entry is not an error: it is detected again
    assert len(got) == 2 and all(d.name != "img_0.png" for d in got.values())


def test_target_lengths_of_absurd_size_are_refused(tmp_path: Path) -> None:
    path = tmp_path / "target.yaml"
    path.write_text(
        "target_type: aprilgrid\ntagCols: 6\ntagRows: 6\ntagSize: 1e300\ntagSpacing: 0.3\n",
        encoding="utf-8",
    )
    _refused(read_target_yaml, path, "'tagSize'")
    with pytest.raises(InputError, match="tagSize must be a positive number"):
        parse_target_short("aprilgrid:6x6:1e300:0.3")


# ----------------------------------------------------------------------------- every number


def _numbers_replaced(kind: str) -> list[tuple[str, bytes]]:
    """The seed of ``kind`` with each of its numbers in turn replaced by each ABSURD value."""
    blob = seeds()[kind]
    out = []
    if kind in YAML_KINDS:
        doc = yaml.safe_load(blob)
        for path in _paths(doc):
            node = doc
            for part in path:
                node = node[part]
            if isinstance(node, bool) or not isinstance(node, (int, float)):
                continue
            for v in ABSURD:
                new = _set(copy.deepcopy(doc), path, "replace", v)
                out.append((f"{path}={v}", yaml.safe_dump(new, sort_keys=False).encode()))
    else:
        for m in NUMBER.finditer(blob):
            for v in ABSURD:
                label = f"{m.group().decode()}@{m.start()}={v}"
                out.append((label, blob[: m.start()] + repr(v).encode() + blob[m.end() :]))
    return out


@pytest.mark.parametrize(
    "kind", [*(k for k in YAML_KINDS if k != "run_config"), "tum", "kitti", "colmap"]
)
def test_every_number_of_absurd_magnitude_reads_or_is_refused(tmp_path: Path, kind: str) -> None:
    """Each number of a valid file, in turn, replaced by an absurd value: every reader of the
    file reads it or raises a one-line InputError (no warning, no other exception)."""
    # (the rig's Kalibr export is left to test_fuzz_readers: this test is exhaustive, and slow)
    readers = [(name, read) for k, name, read in READERS if k == kind and read is not _rig_kalibr]
    for i, (label, blob) in enumerate(_numbers_replaced(kind)):
        folder = tmp_path / str(i)
        folder.mkdir()
        for name, read in readers:
            path = folder / name
            path.write_bytes(blob)
            try:
                read(path)
            except InputError as exc:
                assert "\n" not in str(exc), (label, str(exc))
            except Exception as exc:  # pragma: no cover - a failure's message
                raise AssertionError(f"{kind} {name} {label}: {exc!r}") from exc


def test_seed_numbers_are_found() -> None:
    """The test above replaces numbers in every kind it lists (the seeds hold some)."""
    for kind in ("joint", "relpose", "rig", "intrinsics", "tum"):
        assert len(_numbers_replaced(kind)) >= 5 * len(ABSURD), kind
    assert re.search(rb"\d", seeds()["colmap"])
