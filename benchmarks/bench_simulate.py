"""Simulation speed: the Chen & Che 100 000 s scenario and a 1-hour, 256-beam, 1 Hz multibeam survey.

    ./run bench        (or: python benchmarks/bench_simulate.py)

Prints seconds and soundings per second (ray casting through Open3D included). Nothing asserted.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from tangraph.maps import load
from tangraph.sim.scenario import load_scenario, simulate


def timed(scenario, bathymetry, seed=0):
    simulate(scenario, rng=np.random.default_rng(seed), bathymetry=bathymetry)  # warm up
    t0 = time.perf_counter()
    survey = simulate(scenario, rng=np.random.default_rng(seed), bathymetry=bathymetry)
    return time.perf_counter() - t0, survey


def main() -> None:
    chen = load_scenario("chen2022")
    polar = load(chen.map)
    seconds, survey = timed(chen, polar)
    print(f"chen2022 (100 000 s, 0.01 Hz single beam): {seconds:.3f} s, {survey.n_pings} pings, "
          f"{survey.n_soundings / seconds:,.0f} soundings/s")

    han = load_scenario("han2020")
    chart = load(han.map)
    sonar = dataclasses.replace(han.sonar, n_beams=256, ping_rate=1.0)
    hour = dataclasses.replace(han, sonar=sonar, trajectory={
        "kind": "lawnmower", "origin": [2000.0, 300.0], "heading_deg": 90.0, "line_length": 2100.0,
        "line_spacing": 150.0, "n_lines": 2, "speed": 1.2, "turn_radius": 75.0})
    seconds, survey = timed(hour, chart)
    print(f"multibeam 256 beams, 1 Hz, {survey.time[-1] / 3600:.2f} h on han2020: {seconds:.2f} s, "
          f"{survey.n_soundings:,} soundings, {survey.n_soundings / seconds:,.0f} soundings/s")


if __name__ == "__main__":
    main()
