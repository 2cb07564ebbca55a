"""Shared pytest fixtures, and the Hypothesis profiles (``tests/hypothesis_profiles.py``)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis_profiles import register

# derandomized unless HYPOTHESIS_PROFILE=fuzz (make fuzz): see tests/hypothesis_profiles.py
register()


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded random generator: every test is reproducible."""
    return np.random.default_rng(20240607)
