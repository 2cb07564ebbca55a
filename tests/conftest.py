"""Shared pytest fixtures, and the Hypothesis profiles (``tests/hypothesis_profiles.py``)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis_profiles import register

# derandomized unless HYPOTHESIS_PROFILE=fuzz (make fuzz): see tests/hypothesis_profiles.py
register()

# OpenCV on one thread in the test processes (before any test runs): the e2e runner forks
# them (tests/e2e/cli_runner.py), and OpenCV's worker threads do not survive a fork: a
# child that reconfigured a pool whose threads were gone hung (cv2.setNumThreads in
# calibration, after the worker had rendered images). The child resets OpenCV's default.
cv2.setNumThreads(1)


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded random generator: every test is reproducible."""
    return np.random.default_rng(20240607)


#: The longest modules (seconds of worker time each, measured with a timeline of the suite),
#: run first: xdist's loadscope hands whole modules to the workers in collection order (with
#: ``--no-loadscope-reorder``, as the Makefile runs it; by default xdist 3.8 orders them by
#: their number of tests), and a long module handed out last keeps one worker busy while the
#: other is done (the demo, last, was 80 s of one worker alone).
LONG_MODULES = (
    "tests/e2e/test_demo.py",
    "tests/e2e/test_faults.py",
    "tests/unit/test_core_relpose.py",
    "tests/unit/test_time_offset.py",
    "tests/e2e/test_cli_rig.py",
    "tests/e2e/test_cli_run.py",
    "tests/e2e/test_cli_video.py",
    "tests/unit/test_diagnose.py",
    "tests/e2e/test_cli_report.py",
    "tests/unit/test_rig_bundle.py",
    "tests/unit/test_core_joint.py",
    "tests/e2e/test_cli_recordings.py",
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run :data:`LONG_MODULES` first, in that order (the rest keep theirs)."""
    rank = {name: i for i, name in enumerate(LONG_MODULES)}

    def key(item: pytest.Item) -> int:
        path = item.nodeid.split("::", 1)[0]
        return rank.get(path, len(rank))

    items.sort(key=key)  # stable: each module's tests keep their order
