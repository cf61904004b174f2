"""The checks of settings, in one place: a number within bounds, a count, each refused with a
one-line :class:`~tangraph.errors.TangraphError` naming where it came from and the value.

:func:`number` checks a value; :func:`check_number` and :func:`check_count` check a field of a
frozen dataclass in its ``__post_init__`` (named ``Class.field``) and store the converted value.

Examples
--------
>>> number(2, "trajectory: speed", open_low=True)
2.0
>>> number(True, "trajectory: speed")
Traceback (most recent call last):
...
tangraph.errors.TangraphError: trajectory: speed must be a number, got True
>>> number(-1.0, "SeafloorSettings: std")
Traceback (most recent call last):
...
tangraph.errors.TangraphError: SeafloorSettings: std must be >= 0, got -1.0
"""

from __future__ import annotations

import math
import operator
from typing import Any

from tangraph.errors import TangraphError

__all__ = ["check_count", "check_number", "number"]


def number(value: Any, where: str, *, low: float | None = 0.0, open_low: bool = False,
           high: float | None = None, allow_inf: bool = False) -> float:
    """``value`` as a float within ``[low, high]`` (``(low, high]`` if ``open_low``; no bound
    when None), finite unless ``allow_inf``; else a TangraphError ``"{where} must be ..."``. A
    bool is not a number."""
    if isinstance(value, bool):
        raise TangraphError(f"{where} must be a number, got {value!r}")
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TangraphError(f"{where} must be a number, got {value!r}") from None
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise TangraphError(f"{where} must be finite, got {value!r}")
    if low is not None and (v < low or (open_low and v == low)):
        raise TangraphError(f"{where} must be {'>' if open_low else '>='} {low:g}, got {value!r}")
    if high is not None and v > high:
        raise TangraphError(f"{where} must be <= {high:g}, got {value!r}")
    return v


def check_number(obj: Any, name: str, *, low: float | None = 0.0, open_low: bool = False,
                 high: float | None = None, allow_inf: bool = False) -> float:
    """The field ``obj.name`` checked by :func:`number` (named ``Class.name``) and stored as a
    float (``obj`` may be frozen)."""
    v = number(getattr(obj, name), f"{type(obj).__name__}.{name}", low=low, open_low=open_low, high=high,
               allow_inf=allow_inf)
    object.__setattr__(obj, name, v)
    return v


def check_count(obj: Any, name: str, *, low: int = 1) -> int:
    """The field ``obj.name`` as an int ``>= low`` (not a bool), stored; else a TangraphError
    naming ``Class.name`` and the value."""
    value = getattr(obj, name)
    where = f"{type(obj).__name__}.{name}"
    try:
        v = None if isinstance(value, bool) else operator.index(value)
    except TypeError:
        v = None
    if v is None or v < low:
        raise TangraphError(f"{where} must be an integer >= {low}, got {value!r}")
    object.__setattr__(obj, name, int(v))
    return int(v)
