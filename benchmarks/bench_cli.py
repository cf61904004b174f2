"""Start-up of the command line: ``tangraph --version`` and ``import tangraph`` in a fresh process.

    python benchmarks/bench_cli.py [--repeat 5]

Each command runs in a new interpreter (best of ``--repeat``); the reference measured in the same
run is a bare ``python -c pass``. Target: ``tangraph --version`` under 1 s. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time


def best(command: list[str], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(command, check=True, capture_output=True)
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    python = sys.executable
    bare = best([python, "-c", "pass"], args.repeat)
    for label, command in (
        ("tangraph --version", [python, "-m", "tangraph.cli", "--version"]),
        ("import tangraph", [python, "-c", "import tangraph"]),
        ("import tangraph.maps; BathymetryMap", [python, "-c", "import tangraph.maps as m; m.BathymetryMap"]),
        ("import tangraph.graph (GTSAM)", [python, "-c", "import tangraph.graph"]),
    ):
        seconds = best(command, args.repeat)
        print(f"{label:<38} {seconds:6.3f} s  ({seconds / bare:5.1f} x a bare python start, {bare:.3f} s)")


if __name__ == "__main__":
    main()
