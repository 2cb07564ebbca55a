"""acscal: calibration of articulated camera systems."""

from __future__ import annotations

from acs_cli._version import __version__

__all__ = ["__version__"]
