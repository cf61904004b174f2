"""The configuration every particle filter shares, and the checks all filter configs use.

Configs are frozen dataclasses validated in ``__post_init__``: a bad value raises
:class:`~tangraph.errors.TangraphError` naming the class, the field and the value.
"""

from __future__ import annotations

import dataclasses
import operator
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.resampling import Resampler
from tangraph.survey import Survey

__all__ = ["ParticleConfig", "check_count", "check_number", "survey_sounding_std"]


def check_number(
    obj, name: str, *, low: float | None = 0.0, open_low: bool = False, high: float | None = None
):
    """``obj.name`` as a finite float in ``[low, high]`` (``(low, high]`` if ``open_low``), else a
    :class:`TangraphError` naming the class, field and value."""
    value = getattr(obj, name)
    where = f"{type(obj).__name__}: {name}"
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise TangraphError(f"{where} must be a number, got {value!r}") from None
    if not np.isfinite(v):
        raise TangraphError(f"{where} must be finite, got {value!r}")
    if low is not None and (v < low or (open_low and v == low)):
        raise TangraphError(f"{where} must be {'>' if open_low else '>='} {low:g}, got {value!r}")
    if high is not None and v > high:
        raise TangraphError(f"{where} must be <= {high:g}, got {value!r}")
    object.__setattr__(obj, name, v)
    return v


def check_count(obj, name: str, *, low: int = 1) -> int:
    """``obj.name`` as an int ``>= low``, else a :class:`TangraphError` naming it."""
    value = getattr(obj, name)
    where = f"{type(obj).__name__}: {name}"
    if isinstance(value, bool):
        raise TangraphError(f"{where} must be an integer >= {low}, got {value!r}")
    try:
        v = operator.index(value)
    except TypeError:
        raise TangraphError(f"{where} must be an integer >= {low}, got {value!r}") from None
    if v < low:
        raise TangraphError(f"{where} must be an integer >= {low}, got {value!r}")
    object.__setattr__(obj, name, int(v))
    return int(v)


@dataclasses.dataclass(frozen=True)
class ParticleConfig:
    """Settings shared by the particle filters (each filter's config adds its own).

    Parameters
    ----------
    n_particles : int
        Number of particles.
    init_std : float
        Std (m, per axis) of the initial Gaussian cloud around the first dead-reckoned position.
    process_std, process_fraction : float
        Process noise per ping and axis: ``sqrt(process_std^2 + (process_fraction d)^2)`` m for a
        dead-reckoned displacement of ``d`` m (:class:`~tangraph.filters.MotionModel`).
    sounding_std : float or None
        Std (m) of a sounding's error in the likelihood. None: from the survey
        (:func:`survey_sounding_std`: 1.5 times the sonar's ``depth_noise`` a simulated survey
        records, at least 0.2 m; 1 m when it records none).
    tide, tide_std : float
        Prior of the tide (m, measured = map + tide): mean and std. ``tide_std = 0``: the tide
        is known; otherwise it is estimated per particle (Rao-Blackwellised, see
        :mod:`tangraph.filters.model`).
    resampler : Resampler
        Resampling scheme.
    ess_threshold : float
        Resample when the effective sample size falls below ``ess_threshold * n_particles``.
    reinit_std : float or None
        Spread (m) of the cloud drawn after a divergence; None: ``3 * max(init_std, 1)`` (a
        1 m floor, so that an ``init_std`` of 0 still re-draws a spread cloud).
    reinit_growth : float
        Factor on that spread for each further consecutive divergence.
    """

    n_particles: int = 1000
    init_std: float = 50.0
    process_std: float = 0.5
    process_fraction: float = 0.1
    sounding_std: float | None = None
    tide: float = 0.0
    tide_std: float = 3.0
    resampler: Resampler = Resampler.SYSTEMATIC
    ess_threshold: float = 0.5
    reinit_std: float | None = None
    reinit_growth: float = 2.0

    def __post_init__(self) -> None:
        check_count(self, "n_particles")
        for name in ("init_std", "process_std", "process_fraction", "tide_std"):
            check_number(self, name)
        if self.sounding_std is not None:
            check_number(self, "sounding_std", open_low=True)
        check_number(self, "tide", low=None)
        check_number(self, "ess_threshold", high=1.0)
        check_number(self, "reinit_growth", low=1.0)
        if self.reinit_std is not None:
            check_number(self, "reinit_std", open_low=True)
        try:
            object.__setattr__(self, "resampler", Resampler(self.resampler))
        except ValueError:
            known = ", ".join(r.value for r in Resampler)
            raise TangraphError(
                f"{type(self).__name__}: resampler must be one of {known}, got {self.resampler!r}"
            ) from None

    @property
    def reinit_spread(self) -> float:
        """Spread (m) of the first re-initialisation after a divergence."""
        return float(self.reinit_std) if self.reinit_std is not None else 3.0 * max(self.init_std, 1.0)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (enums as their values), as stored in ``Track.meta["config"]``."""
        return {k: (v.value if hasattr(v, "value") else v) for k, v in dataclasses.asdict(self).items()}


def survey_sounding_std(survey: Survey | None) -> float:
    """The likelihood's sounding std for a survey: 1.5 times the sonar ``depth_noise`` recorded in
    ``survey.meta["settings"]["sonar"]`` (simulated surveys; the margin covers map interpolation
    and attitude errors), at least 0.2 m; 1 m when the survey records none.

    Examples
    --------
    >>> survey_sounding_std(None)
    1.0
    """
    try:
        noise = float(survey.meta["settings"]["sonar"]["depth_noise"])  # type: ignore[union-attr]
    except (AttributeError, KeyError, TypeError, ValueError):
        return 1.0
    return max(1.5 * noise, 0.2) if np.isfinite(noise) and noise >= 0 else 1.0
