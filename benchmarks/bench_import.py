"""Speed of importing a recorded survey: the 97-minute Lake Caputh RiverSurveyor run (5839 samples).

    python benchmarks/bench_import.py [--data DIR]

Times :func:`tangraph.formats.import_sontek_sum` (read, DMS parsing, time zone, projection, DR,
footprints, water level) and, as the reference measured in the same run, ``pandas.read_csv`` of
the same file (text to columns, nothing converted). Target: a 90-minute run in under 5 s.
Needs the data folder (default ``../shared/data/caputh`` beside the checkout); nothing is asserted.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from _timing import best_time

RUN = "20250327110103.sum"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = Path(__file__).resolve().parents[2] / "shared" / "data" / "caputh"
    parser.add_argument("--data", type=Path, default=default, help="the Lake Caputh folder")
    args = parser.parse_args()
    path = args.data / RUN
    if not path.is_file():
        print(f"bench_import: {path} is absent; skipped")
        return
    import pandas as pd

    from tangraph.formats import import_sontek_sum

    logging.getLogger("tangraph").setLevel(logging.ERROR)  # the GPS-referenced velocity warning

    def run():
        return import_sontek_sum(path, crs="EPSG:25833", timezone="Europe/Berlin",
                                 water_level=args.data / "waterlevel.csv")

    survey = run()
    ours = best_time(run, 5)
    reference = best_time(lambda: pd.read_csv(path, encoding="latin-1", lineterminator="\r"), 5)
    minutes = survey.time[-1] / 60
    print(f"import_sontek_sum: {survey.n_pings} samples ({minutes:.0f} min) in {ours:.3f} s "
          f"(target 5 s); pandas.read_csv of the file {reference:.3f} s: ratio {ours / reference:.1f}")


if __name__ == "__main__":
    main()
