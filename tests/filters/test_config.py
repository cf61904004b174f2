"""The filters' settings (tangraph.filters.config and each method's config): a bad particle count or
setting is refused naming the config and the field; the health settings are their own part."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import (
    FilterHealth,
    IPFConfig,
    JBPFConfig,
    MLEConfig,
    PFConfig,
    SJCPFConfig,
    TercomPFConfig,
)


@pytest.mark.parametrize("value", [0, -5, 2.5, True, "10"])
def test_bad_particle_count_is_named(value):
    for cls in (PFConfig, IPFConfig, SJCPFConfig, JBPFConfig, TercomPFConfig):
        with pytest.raises(TangraphError, match=f"{cls.__name__}.n_particles"):
            cls(n_particles=value)


@pytest.mark.parametrize(
    ("cls", "field", "value"),
    [
        (PFConfig, "tempering_ess", 0.0),
        (PFConfig, "process_floor", -1.0),
        (PFConfig, "kernel_bandwidth", np.nan),
        (PFConfig, "kernel_bandwidth", 1.5),
        (PFConfig, "kernel_floor", -1.0),
        (PFConfig, "kernel_ess", 0.0),
        (SJCPFConfig, "kernel_ess", 1.5),
        (PFConfig, "max_stages", 0),
        (FilterHealth, "lost_alpha", 0.0),
        (FilterHealth, "lost_pings", 0),
        (PFConfig, "ess_threshold", 1.5),
        (PFConfig, "resampler", "bogus"),
        (FilterHealth, "reinit_std", 0.0),
        (FilterHealth, "reinit_growth", 0.5),
        (SJCPFConfig, "window", 2),
        (SJCPFConfig, "kernel", "gaussian"),
        (SJCPFConfig, "correlation", "cosine"),
        (SJCPFConfig, "jitter_std", -1.0),
        (JBPFConfig, "jitter_std", -1.0),
        (TercomPFConfig, "criterion", "mad"),
        (TercomPFConfig, "window", 0),
        (TercomPFConfig, "gate", 0.0),
        (MLEConfig, "window", 0),
        (MLEConfig, "max_half_width", -3.0),
    ],
)
def test_bad_configuration_is_named(cls, field, value):
    with pytest.raises(TangraphError, match=f"{cls.__name__}.{field}"):
        cls(**{field: value})


def test_the_health_settings_are_their_own_part():
    """A filter's lost test, gate and recovery settings live in its ``health``; ``replace``
    takes them by name, a table is read as one, anything else is refused naming the field."""
    config = PFConfig(n_particles=300).replace(ping_gate=True, lost_pings=4, n_particles=200)
    assert (config.n_particles, config.health.ping_gate, config.health.lost_pings) == (200, True, 4)
    assert config.health.gate_pings == FilterHealth().gate_pings
    assert PFConfig(health={"ping_gate": True}).health == FilterHealth(ping_gate=True)
    assert config.as_dict()["health"]["lost_pings"] == 4
    with pytest.raises(TangraphError, match="PFConfig.health must be a FilterHealth, got int"):
        PFConfig(health=3)
    with pytest.raises(TypeError):
        PFConfig(ping_gate=True)  # type: ignore[call-arg]
