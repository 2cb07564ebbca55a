"""Hypothesis settings profiles: the property tests are reproducible unless asked to fuzz.

``tests/conftest.py`` registers two profiles and loads the one ``HYPOTHESIS_PROFILE`` names:

- ``default`` (``pytest``, ``make test``): derandomized, so every run draws the same
  examples (a CI failure is a failure on every machine, and a pass does not flake); no
  deadline (a loaded machine is not a failure); no example database (nothing written into
  the checkout, nothing replayed from an earlier run); a failure prints its reproduction
  blob.
- ``fuzz`` (``HYPOTHESIS_PROFILE=fuzz``, ``make fuzz``): fresh randomness on every run and
  :data:`FUZZ_FACTOR` times the examples (``ACSCAL_FUZZ_SCALE`` overrides the factor); a
  failure is saved in ``.hypothesis/`` and replayed first on the next fuzz run.

A test that sets its own ``max_examples`` passes it through :func:`examples`, so that the
fuzz profile scales it too.
"""

from __future__ import annotations

import os

from hypothesis import settings

PROFILE = os.environ.get("HYPOTHESIS_PROFILE", "default")
#: How many times more examples a property test draws under the fuzz profile.
FUZZ_FACTOR = 10.0
#: The factor in effect: ``ACSCAL_FUZZ_SCALE`` if set, else :data:`FUZZ_FACTOR` when fuzzing.
SCALE = float(os.environ.get("ACSCAL_FUZZ_SCALE", FUZZ_FACTOR if PROFILE == "fuzz" else 1.0))


def examples(n: int) -> int:
    """``max_examples`` for a test that draws ``n`` by default (scaled under fuzz)."""
    return max(1, round(n * SCALE))


def register() -> None:
    """Register the ``default`` and ``fuzz`` profiles and load ``HYPOTHESIS_PROFILE``'s."""
    # fuzz first: it inherits Hypothesis's own defaults (the example database in
    # .hypothesis/), which re-registering the loaded "default" profile replaces
    settings.register_profile(
        "fuzz",
        derandomize=False,
        deadline=None,
        max_examples=examples(100),
        print_blob=True,
    )
    settings.register_profile(
        "default", derandomize=True, deadline=None, database=None, print_blob=True
    )
    settings.load_profile(PROFILE)
