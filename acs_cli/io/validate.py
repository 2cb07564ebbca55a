"""Small validators for values read from artifacts: one place, one wording.

Every function takes the raw value (as YAML or an NPZ gives it), the artifact's key (a
dotted name such as ``"joint.position_in_a"``, named in the message) and the artifact's
file, and returns a checked value or raises :class:`~acs_cli.errors.InputError` naming
the file and the key. The ``optional_*`` variants return ``None`` for a missing (``None``)
value.
"""

from __future__ import annotations

import reprlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from acs_cli.errors import InputError

__all__ = [
    "COV_TOL",
    "MAX_MAGNITUDE",
    "MIN_EXTENT",
    "TIME_TOL",
    "as_bool",
    "as_covariance3",
    "as_int",
    "as_mapping",
    "as_matrix",
    "as_number",
    "as_scale",
    "as_str_list",
    "as_vector",
    "check_magnitude",
    "listed_mask",
    "optional_covariance3",
    "optional_matrix",
    "optional_number",
    "optional_vector",
    "short_repr",
]

FloatArray = NDArray[np.floating[Any]]
Source = str | Path | None

#: Largest difference (seconds or frame numbers) for two timestamps to be the same sample.
TIME_TOL = 1e-6
#: Relative tolerance of a covariance's symmetry and of its smallest eigenvalue (PSD).
COV_TOL = 1e-6
#: Largest magnitude of a length (a translation, a joint position) or an angle acscal
#: reads, in the file's units: 1e10 holds UTM coordinates in millimetres; beyond, a value
#: is a wrong unit or a corrupt file, and the estimators' squares and products overflow.
MAX_MAGNITUDE = 1e10
#: Smallest non-zero extent of a trajectory (its largest translation component), in its
#: units: smaller, the estimators' fourth powers underflow (they fail near 1e-50).
MIN_EXTENT = 1e-20


_REPR = reprlib.Repr()
_REPR.maxlevel = 2
_REPR.maxlist = _REPR.maxtuple = _REPR.maxdict = _REPR.maxset = 4
_REPR.maxstring = _REPR.maxother = 40


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)`` for a message, bounded: at most ``limit`` characters, computed
    without building the whole repr of a huge value (a long list, a deep mapping)."""
    text = _REPR.repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def check_magnitude(
    values: Any, key: str, path: Source, *, extent: bool = False, squared: bool = False
) -> None:
    """Refuse finite values beyond :data:`MAX_MAGNITUDE` (NaN and inf are left to the
    caller); with ``extent``, also a non-zero set of values all below :data:`MIN_EXTENT`
    (a trajectory's translations); with ``squared``, values in squared units (variances,
    covariances) beyond ``MAX_MAGNITUDE ** 2``.

    Parameters
    ----------
    values : array_like of float
        The numbers (any shape).
    key : str
        What they are (``"translations"``, ``"joint.position_in_a"``), for the message.
    path : str or Path or None
        Their file, for the message.
    extent : bool
        Also check the smallest scale.
    squared : bool
        The values are in the file's units squared: the limit is ``MAX_MAGNITUDE ** 2``.

    Raises
    ------
    InputError
        Naming ``key``, the offending value and the range.
    """
    arr = np.abs(np.asarray(values, dtype=float))
    finite = arr[np.isfinite(arr)]
    largest = float(finite.max(initial=0.0))
    limit = MAX_MAGNITUDE**2 if squared else MAX_MAGNITUDE
    if largest > limit:
        units = "the file's units, squared" if squared else "the file's units"
        raise InputError(
            f"'{key}' holds {largest:.3g}, beyond the {limit:.0e} in size acscal "
            f"accepts (in {units}): a wrong unit, or a corrupt file?",
            path=path,
        )
    if extent and 0.0 < largest < MIN_EXTENT:
        raise InputError(
            f"'{key}' are all below {MIN_EXTENT:.0e} in size (the largest is {largest:.3g}), "
            "too small to compute with: give them in a larger unit",
            path=path,
        )


def _floats(value: Any) -> FloatArray | None:
    """``value`` as a float array, or None when it is not numeric (strings, ragged lists)."""
    if isinstance(value, (str, bytes, Mapping)) or value is None:
        return None
    try:
        with np.errstate(all="ignore"):
            arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return None
    if arr.dtype.kind != "f":  # pragma: no cover - dtype=float always gives floats
        return None
    return arr


def as_number(
    value: Any,
    key: str,
    path: Source,
    *,
    positive: bool = False,
    non_negative: bool = False,
    allow_nan: bool = False,
) -> float:
    """A finite number (not a bool).

    Parameters
    ----------
    value : Any
        The raw value.
    key : str
        The artifact key, for the message.
    path : str or Path or None
        The artifact's file, for the message.
    positive, non_negative : bool
        Also require ``> 0`` or ``>= 0``.
    allow_nan : bool
        Accept NaN and inf (e.g. a standard deviation that could not be computed).

    Returns
    -------
    float

    Raises
    ------
    InputError
        Not a finite number, or of the wrong sign.
    """
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating))
    if ok:
        try:
            v = float(value)
        except OverflowError:  # an int beyond float range
            ok = False
        else:
            ok = allow_nan or bool(np.isfinite(v))
    if not ok:
        raise InputError(f"'{key}' must be a finite number, got {short_repr(value)}", path=path)
    if positive and not v > 0:
        raise InputError(f"'{key}' must be a positive number, got {v!r}", path=path)
    if non_negative and not v >= 0:
        raise InputError(f"'{key}' must not be negative, got {v!r}", path=path)
    return v


def optional_number(value: Any, key: str, path: Source, **kwargs: Any) -> float | None:
    """:func:`as_number`, or ``None`` for ``None``."""
    return None if value is None else as_number(value, key, path, **kwargs)


def as_int(value: Any, key: str, path: Source, *, minimum: int | None = None) -> int:
    """An integer that fits an int32 (an integral float is accepted), not a bool.

    Raises
    ------
    InputError
        Not an integer, out of the int32 range, or below ``minimum``.
    """
    ok = False
    if not isinstance(value, bool) and isinstance(value, (int, np.integer)):
        ok = abs(int(value)) < 2**31
    elif isinstance(value, (float, np.floating)):
        v = float(value)
        ok = bool(np.isfinite(v)) and v.is_integer() and abs(v) < 2**31
    if not ok:
        raise InputError(f"'{key}' must be an integer, got {short_repr(value)}", path=path)
    n = int(value)
    if minimum is not None and n < minimum:
        raise InputError(f"'{key}' must be at least {minimum}, got {n}", path=path)
    return n


def as_bool(value: Any, key: str, path: Source) -> bool:
    """A YAML boolean (``true``/``false``)."""
    if not isinstance(value, (bool, np.bool_)):
        raise InputError(f"'{key}' must be true or false, got {short_repr(value)}", path=path)
    return bool(value)


def as_matrix(
    value: Any,
    shape: tuple[int, ...],
    key: str,
    path: Source,
    *,
    allow_nan: bool = False,
    squared: bool = False,
) -> FloatArray:
    """Finite numbers of the given shape, none beyond :data:`MAX_MAGNITUDE`.

    Parameters
    ----------
    value : Any
        Nested lists (YAML) or an array.
    shape : tuple of int
        The required shape, e.g. ``(4, 4)``.
    key, path
        For the message.
    allow_nan : bool
        Accept NaN and inf entries (standard deviations, covariances that could not be
        computed).
    squared : bool
        The entries are in squared units (a covariance): the limit is ``MAX_MAGNITUDE ** 2``
        (:func:`check_magnitude`).

    Raises
    ------
    InputError
        Not numbers, another shape, a NaN/inf, or an entry beyond the limit.
    """
    arr = _floats(value)
    what = "x".join(map(str, shape))
    if arr is None or arr.shape != shape or not (allow_nan or np.all(np.isfinite(arr))):
        got = "" if arr is None else f", got shape {arr.shape}"
        raise InputError(f"'{key}' must be a finite {what} array{got}", path=path)
    check_magnitude(arr, key, path, squared=squared)
    return arr


def optional_matrix(
    value: Any,
    shape: tuple[int, ...],
    key: str,
    path: Source,
    *,
    allow_nan: bool = False,
    squared: bool = False,
) -> FloatArray | None:
    """:func:`as_matrix`, or ``None`` for ``None``."""
    if value is None:
        return None
    return as_matrix(value, shape, key, path, allow_nan=allow_nan, squared=squared)


def as_scale(value: Any, key: str, path: Source) -> float:
    """A scale factor or a ratio of units: a number within ``[1 / MAX_MAGNITUDE,
    MAX_MAGNITUDE]`` (beyond, lengths multiplied or divided by it overflow).

    Raises
    ------
    InputError
        Not a finite positive number, or outside that range.
    """
    v = as_number(value, key, path, positive=True)
    if not 1.0 / MAX_MAGNITUDE <= v <= MAX_MAGNITUDE:
        raise InputError(
            f"'{key}' is {v:.3g}, outside the [{1.0 / MAX_MAGNITUDE:.0e}, {MAX_MAGNITUDE:.0e}] "
            "acscal accepts for a scale: a wrong unit, or a corrupt file?",
            path=path,
        )
    return v


def as_vector(
    value: Any, key: str, path: Source, n: int = 3, *, allow_nan: bool = False
) -> FloatArray:
    """``n`` finite numbers (default 3: a point or a vector in some frame).

    ``allow_nan`` accepts NaN and inf entries (a standard deviation not computed).

    Raises
    ------
    InputError
        Not ``n`` finite numbers, or one beyond :data:`MAX_MAGNITUDE`; the message names
        ``key`` and the file.
    """
    arr = _floats(value)
    if arr is None or arr.shape != (n,) or not (allow_nan or np.all(np.isfinite(arr))):
        words = {3: "three"}.get(n, str(n))
        raise InputError(f"'{key}' must be {words} finite numbers", path=path)
    check_magnitude(arr, key, path)
    return arr


def optional_vector(
    value: Any, key: str, path: Source, n: int = 3, *, allow_nan: bool = False
) -> FloatArray | None:
    """:func:`as_vector`, or ``None`` for ``None``."""
    return None if value is None else as_vector(value, key, path, n, allow_nan=allow_nan)


def as_covariance3(value: Any, key: str, path: Source) -> FloatArray:
    """A 3x3 covariance: finite, within ``MAX_MAGNITUDE ** 2``, symmetric and positive
    semi-definite.

    Both checks are made on the correlation matrix ``C_ij / (s_i s_j)`` (``s_i`` the standard
    deviations, floored at ``sqrt(COV_TOL)`` times the largest), within :data:`COV_TOL`: a
    covariance whose axes differ by orders of magnitude is judged on each axis's own scale.
    An entry larger than the largest variance (which no covariance has) is refused before
    any division, so no value overflows.

    Raises
    ------
    InputError
        Not a finite 3x3 matrix, an entry beyond ``MAX_MAGNITUDE ** 2`` (a variance in the
        file's units squared), not symmetric, or with a negative eigenvalue.
    """
    C = as_matrix(value, (3, 3), key, path, squared=True)
    diag = np.diag(C)
    top = float(diag.max())
    not_psd = f"'{key}' must be a positive semi-definite 3x3 covariance"
    if top <= 0.0:
        if np.any(C != 0.0):
            raise InputError(f"{not_psd} (its diagonal is not positive)", path=path)
        return C
    # |R - R^T| > COV_TOL for R = C / (s s^T), without dividing (entries within 1e20)
    s = np.sqrt(np.maximum(diag, COV_TOL * top))
    if np.any(np.abs(C - C.T) > COV_TOL * np.outer(s, s)):
        raise InputError(f"'{key}' must be a symmetric 3x3 covariance", path=path)
    if diag.min() < 0.0:
        raise InputError(f"{not_psd} (a variance is negative)", path=path)
    if float(np.abs(C).max()) > top * (1.0 + COV_TOL):
        # |C_ij| <= sqrt(C_ii C_jj) <= top for every covariance
        raise InputError(f"{not_psd} (an entry exceeds the largest variance)", path=path)
    Cn = C / top  # entries within 1 + COV_TOL: nothing below overflows or divides by 0
    sn = np.sqrt(np.maximum(np.diag(Cn), COV_TOL))
    R = Cn / np.outer(sn, sn)
    if np.linalg.eigvalsh(0.5 * (R + R.T)).min() < -COV_TOL:
        raise InputError(f"{not_psd} (it has a negative eigenvalue)", path=path)
    return C


def optional_covariance3(value: Any, key: str, path: Source) -> FloatArray | None:
    """:func:`as_covariance3`, or ``None`` for ``None``."""
    return None if value is None else as_covariance3(value, key, path)


def as_mapping(value: Any, key: str, path: Source) -> dict[str, Any]:
    """A mapping (with string keys, as YAML gives them)."""
    if not isinstance(value, Mapping):
        raise InputError(f"'{key}' must be a mapping", path=path)
    return {str(k): v for k, v in value.items()}


def as_str_list(value: Any, key: str, path: Source) -> list[str]:
    """A list of strings (``None`` is the empty list; other scalars are refused)."""
    if value is None:
        return []
    if not isinstance(value, (list, tuple)):
        raise InputError(f"'{key}' must be a list", path=path)
    return [str(v) for v in value]


def listed_mask(labels: NDArray[Any], listed: Any) -> NDArray[np.bool_]:
    """Which of ``labels`` (timestamps or indices, shape ``(n,)``) appear in ``listed``.

    Parameters
    ----------
    labels : ndarray, shape (n,)
        Timestamps (s) or frame numbers.
    listed : sequence of numbers
        E.g. an artifact's ``quality.frames.rejected``; entries within :data:`TIME_TOL`
        match. Non-numbers are ignored.

    Returns
    -------
    ndarray of bool, shape (n,)
    """
    lab = np.asarray(labels, dtype=float).reshape(-1)
    mask = np.zeros(lab.shape[0], dtype=bool)
    if isinstance(listed, (list, tuple, np.ndarray)):
        vals = np.asarray(
            [
                float(v)
                for v in listed
                if not isinstance(v, bool) and isinstance(v, (int, float, np.integer, np.floating))
            ],
            dtype=float,
        )
        if vals.size and lab.size:
            mask = np.any(np.abs(lab[:, None] - vals[None, :]) <= TIME_TOL, axis=1)
    return mask
