"""Argument checks shared by the public entry points: each failure is a ValueError that names the argument."""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

#: Largest magnitude a weight or control may have: a sum of 32 squared differences of such values stays finite in
#: float32 (max 3.4e38), so the winner search never compares infinities.
MAX_MAGNITUDE = 1e18


def finite_array(name: str, value, ndim: int, dtype=np.float32) -> np.ndarray:
    """`value` as a C-contiguous array of `dtype` (a copy) with `ndim` dimensions and only finite entries."""
    if isinstance(value, np.ndarray) and value.dtype in (np.float32, np.float64) and value.ndim == ndim:
        # the common case (a drag's controls, every frame): one pass, no float64 copy (a NaN's max is NaN and an
        # infinity's exceeds the limit: both fail the comparison); anything wrong is described by the general path
        limit = MAX_MAGNITUDE if dtype is np.float32 or np.issubdtype(dtype, np.floating) else math.inf
        if value.size == 0 or np.abs(value).max() <= limit:
            return np.array(value, dtype=dtype, order="C")
    try:
        arr = np.asarray(value)
    except Exception as exc:  # ragged lists and the like
        raise ValueError(f"{name}: expected a numeric array, got {type(value).__name__} ({exc})") from None
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise ValueError(f"{name}: expected a numeric array, got dtype {arr.dtype}")
    if arr.ndim != ndim:
        raise ValueError(f"{name}: expected {ndim} dimensions, got shape {arr.shape}")
    if np.issubdtype(arr.dtype, np.complexfloating):
        raise ValueError(f"{name}: expected real numbers, got complex")
    arr64 = arr.astype(np.float64)
    bad = ~np.isfinite(arr64)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        raise ValueError(f"{name}: entries must be finite; found {arr64[where]} at index {where}")
    limit = MAX_MAGNITUDE if np.issubdtype(dtype, np.floating) else math.inf
    if np.abs(arr64).max(initial=0.0) > limit:
        raise ValueError(f"{name}: values must satisfy |x| <= {limit:.0e}, so that squared distances stay finite in "
                         f"float32; found {np.abs(arr64).max():.3g}")
    return np.ascontiguousarray(arr64.astype(dtype))


def index_array(name: str, value, ndim: int | None = None) -> np.ndarray:
    """`value` as an int64 array; non-integers (1.5, "a", True) are refused."""
    arr = np.asarray(value)
    if arr.dtype == bool or not (np.issubdtype(arr.dtype, np.integer) or arr.size == 0):
        raise ValueError(f"{name}: expected integer indices, got dtype {arr.dtype}")
    if ndim is not None and arr.ndim != ndim:
        raise ValueError(f"{name}: expected {ndim} dimensions, got shape {arr.shape}")
    return arr.astype(np.int64).reshape(arr.shape)


def integer(name: str, value, minimum: int, maximum: int | None = None) -> int:
    """An int in [minimum, maximum]; bools and non-integral numbers are refused."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, (float, np.floating)) and math.isfinite(value) and float(value).is_integer():
            value = int(value)
        else:
            raise ValueError(f"{name}: expected an integer, got {value!r}")
    value = int(value)
    if value < minimum or (maximum is not None and value > maximum):
        upper = "" if maximum is None else f" and at most {maximum}"
        raise ValueError(f"{name}: expected at least {minimum}{upper}, got {value}")
    return value


def runs(name: str, lengths, total: int) -> tuple[int, ...]:
    """Run lengths, each an integer >= 1, that add up to `total` (the strokes of a list of controls)."""
    out = tuple(integer(f"{name}[{i}]", n, 1) for i, n in enumerate(lengths))
    if sum(out) != total:
        raise ValueError(f"{name}: the runs' lengths {list(out)} sum to {sum(out)}, not to the {total} controls")
    return out


def choice(name: str, value, options: tuple[str, ...]) -> str:
    """One of `options`."""
    if value not in options:
        raise ValueError(f"{name}: expected one of {', '.join(map(repr, options))}, got {value!r}")
    return value


def real(name: str, value, low: float, high: float, low_open: bool = False) -> float:
    """A finite float in [low, high] (or (low, high] when low_open)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(x):
        raise ValueError(f"{name}: expected a finite number, got {value!r}")
    ok = (low < x if low_open else low <= x) and x <= high
    if not ok:
        interval = f"{'(' if low_open else '['}{low}, {high}]"
        raise ValueError(f"{name}: expected a value in {interval}, got {x}")
    return x


def dims(name: str, value: Iterable | None, n_dims: int) -> tuple[int, ...]:
    """A sorted tuple of distinct feature-dimension indices, each in [0, n_dims)."""
    if value is None:
        return ()
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (value,)
    out = []
    for d in value:
        if isinstance(d, bool) or not isinstance(d, (int, np.integer)):
            raise ValueError(f"{name}: expected feature-dimension indices (ints), got {d!r}")
        if not 0 <= int(d) < n_dims:
            raise ValueError(f"{name}: dimension {int(d)} is outside the {n_dims} feature dimensions (0..{n_dims - 1})")
        out.append(int(d))
    return tuple(sorted(set(out)))


def integer_text(name: str, value, minimum: int, maximum: int | None = None) -> int:
    """`integer`, also taking a whole number written as text ("600", " 1e3 "), as a form field sends it."""
    if isinstance(value, str):
        try:
            value = float(value.strip())
        except ValueError:
            raise ValueError(f"{name}: expected an integer, got {value!r}") from None
    return integer(name, value, minimum, maximum)


def finite_vector(name: str, value, length: int, bound: float | None = None) -> np.ndarray:
    """`value` as a float32 vector of `length` finite entries (`finite_array`), each with |x| <= bound if given."""
    arr = finite_array(name, value, 1, np.float64)
    if arr.shape[0] != length:
        raise ValueError(f"{name}: expected {length} numbers, got {arr.shape[0]}")
    if bound is not None and np.abs(arr).max(initial=0.0) > bound:
        raise ValueError(f"{name}: values must lie within +-{bound:g}, got {arr.tolist()}")
    return arr.astype(np.float32)
