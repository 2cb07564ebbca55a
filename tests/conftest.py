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
