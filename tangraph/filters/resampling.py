"""Resampling schemes: multinomial, systematic, stratified and residual, vectorised."""

from __future__ import annotations

import enum
import operator

import numpy as np

from tangraph.errors import TangraphError

__all__ = ["Resampler", "resample"]


class Resampler(enum.StrEnum):
    MULTINOMIAL = "multinomial"
    SYSTEMATIC = "systematic"
    STRATIFIED = "stratified"
    RESIDUAL = "residual"


def _checked(weights) -> np.ndarray:
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.size < 1 or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
        raise TangraphError(
            "weights must be a non-empty 1-D array of finite, non-negative numbers with a positive sum"
        )
    return w / w.sum()


def _search(w: np.ndarray, u: np.ndarray) -> np.ndarray:
    cumulative = np.cumsum(w)
    cumulative[-1] = 1.0
    return np.minimum(np.searchsorted(cumulative, u, side="right"), w.size - 1)


def resample(
    weights, scheme: Resampler | str = Resampler.SYSTEMATIC, *, rng: np.random.Generator, n: int | None = None
) -> np.ndarray:
    """Indices (n,) of the particles kept, drawn by ``scheme``; the weights are not modified.
    ``n`` (default: the number of weights) must be an integer >= 1.

    Examples
    --------
    >>> import numpy as np
    >>> resample([0.0, 1.0, 0.0], "systematic", rng=np.random.default_rng(0)).tolist()
    [1, 1, 1]
    """
    w = _checked(weights)
    if n is None:
        n = w.size
    else:
        try:
            count = operator.index(n)
        except TypeError:
            count = 0
        if isinstance(n, bool) or count < 1:
            raise TangraphError(f"resample: n must be an integer >= 1, got {n!r}")
        n = int(count)
    try:
        scheme = Resampler(scheme)
    except ValueError:
        known = ", ".join(r.value for r in Resampler)
        raise TangraphError(f"resample: scheme must be one of {known}, got {scheme!r}") from None
    if scheme is Resampler.MULTINOMIAL:
        return _search(w, rng.random(n))
    if scheme is Resampler.SYSTEMATIC:
        return _search(w, (rng.random() + np.arange(n)) / n)
    if scheme is Resampler.STRATIFIED:
        return _search(w, (rng.random(n) + np.arange(n)) / n)
    copies = np.floor(n * w).astype(np.int64)  # residual: the whole parts, then the rest at random
    fixed = np.repeat(np.arange(w.size), copies)
    rest = n - fixed.size
    if rest == 0:
        return fixed
    remainder = n * w - copies
    return np.concatenate([fixed, _search(remainder / remainder.sum(), rng.random(rest))])
