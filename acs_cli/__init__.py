"""acscal: calibration of articulated camera systems."""

from __future__ import annotations

__all__ = ["__version__"]


def __getattr__(name: str) -> str:
    """``acs_cli.__version__``, read from the installed package's metadata on first use.

    Importing :mod:`importlib.metadata` costs tens of milliseconds, at every start of
    ``acscal`` if done here at import; only ``--version`` and the artifacts need it.
    """
    if name != "__version__":
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        value = version("acscal")
    except PackageNotFoundError:  # pragma: no cover - a source tree without install
        value = "0.0.0+unknown"
    globals()["__version__"] = value
    return value
