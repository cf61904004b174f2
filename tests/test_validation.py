"""tangraph.validation: the one place settings are checked (a number within bounds, a count)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.validation import check_count, check_number, number


@pytest.mark.parametrize("value, kwargs, message", [
    (True, {}, "must be a number, got True"),
    ("ten", {}, "must be a number, got 'ten'"),
    (None, {}, "must be a number, got None"),
    (math.nan, {}, "must be finite, got nan"),
    (math.inf, {}, "must be finite, got inf"),
    (-0.5, {}, "must be >= 0, got -0.5"),
    (0.0, {"open_low": True}, "must be > 0, got 0.0"),
    (2.0, {"high": 1.0}, "must be <= 1, got 2.0"),
    (-3.0, {"low": -2.0}, "must be >= -2, got -3.0"),
])
def test_number_refuses_naming_where_and_value(value, kwargs, message):
    with pytest.raises(TangraphError, match=f"^cfg.toml: speed {message}$"):
        number(value, "cfg.toml: speed", **kwargs)


def test_number_accepts_and_converts():
    assert number(np.float32(2.5), "x") == 2.5 and isinstance(number(np.int64(3), "x"), float)
    assert number(0.0, "x") == 0.0 and number(-7.0, "x", low=None) == -7.0
    assert number(math.inf, "x", allow_inf=True) == math.inf
    assert number(1.0, "x", high=1.0) == 1.0


@dataclasses.dataclass(frozen=True)
class _Settings:
    rate: object = 1
    count: object = 2


def test_check_number_and_count_store_on_a_frozen_dataclass():
    s = _Settings(rate=np.float64(0.5), count=np.int32(4))
    assert check_number(s, "rate", open_low=True) == 0.5 and type(s.rate) is float
    assert check_count(s, "count", low=1) == 4 and type(s.count) is int
    with pytest.raises(TangraphError, match=r"^_Settings.rate must be > 0, got 0$"):
        check_number(_Settings(rate=0), "rate", open_low=True)


@pytest.mark.parametrize("value", [True, 2.0, "3", 0, -1])
def test_check_count_refuses_what_is_not_a_count(value):
    with pytest.raises(TangraphError, match=rf"^_Settings.count must be an integer >= 1, got {value!r}$"):
        check_count(_Settings(count=value), "count")
