"""Lake Caputh: the long run navigated on the study's map with its error statement changed.

    python experiments/caputh_replay/statement.py MAP.nc [--gap G] [--change C] [--cases ...]
                                                  [--methods ...] [--data DIR]

``MAP.nc`` is the map a ``caputh_replay`` run wrote to its output folder (``map.nc``). Its filled
cells' ``depth_std`` is multiplied by ``--gap`` and ``--change`` m are added in quadrature to
every cell's, then the long March run (20250327110103) is navigated with ``config.toml``'s
settings for each DR case and method, and scored against its GPS as the study scores it. The
figures the study's README quotes take 0.33 and 0.17 m, what the March runs' GPS says of the
map (``error_by_cell`` in ``checks.json``): a statement made to hold sounding by sounding by an
oracle, to see what such a statement would give the estimators, not a setting.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import run as study  # noqa: E402  (the study's own functions, beside this file)

LONG_RUN = "20250327110103"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("map", type=Path, help="the map.nc of a caputh_replay output folder")
    parser.add_argument("--gap", type=float, default=1.0, help="factor of the filled cells' std")
    parser.add_argument("--change", type=float, default=0.0, help="m added in quadrature to every cell's std")
    parser.add_argument("--cases", nargs="+", default=["boat+spoiled"], choices=study.CASES)
    parser.add_argument("--methods", nargs="+", default=["smoother", "isam2"], choices=study.GRAPH)
    parser.add_argument("--data", type=Path, default=study.DEFAULT_DATA)
    args = parser.parse_args(argv)

    import xarray as xr

    from tangraph.maps import read_map
    from tangraph.navigation import navigate

    cfg = study.load_config(HERE / "config.toml")
    bathymetry = read_map(args.map)
    with xr.open_dataset(args.map) as ds:
        filled = ds["filled"].values > 0
    std = np.where(filled, args.gap * bathymetry.depth_std, bathymetry.depth_std)
    bathymetry = bathymetry.replace(depth_std=np.sqrt(std**2 + args.change**2))
    print(f"gap x {args.gap:g}, change {args.change:g} m: median (m), ANEES, final NEES, fixes used")
    for case in args.cases:
        survey = study.dr_case(cfg, args.data, args.data / f"{LONG_RUN}.sum", case, bathymetry)
        for method in args.methods:
            model, settings = study.estimator(cfg, case, method)
            track = navigate(survey, bathymetry, method, settings, rng=np.random.default_rng(0), model=model)
            s = study.scores(track, survey, cfg["reference"]["gps_std"])
            print(f"{case} {method}: {s['median']:.2f}, {s['anees']:.2f}, {s['final_nees']:.2f}, "
                  f"{s['fixes_accepted']}/{s['fixes']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
