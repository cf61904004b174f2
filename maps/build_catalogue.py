"""Rebuild the files of the map catalogue from the packages that ship them.

Run once by a maintainer (not at install or run time); it needs the wheels `anuga==4.1.0`,
`lidar==0.8.4` and `isobath==0.1.0` unpacked (or installed) and Debian's `ferret-datasets`.

    python maps/build_catalogue.py --wheels DIR_WITH_UNPACKED_WHEELS

The catalogue keeps each file as shipped, except ETOPO5, of which only the Arctic crop of the
SJCPF paper is kept (37 MB -> a few kB), with its longitude axis rebuilt.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np
import xarray as xr

HERE = Path(__file__).resolve().parent
ETOPO5 = Path("/usr/share/ferret-vis/data/etopo5.cdf")
# The SJCPF region is 75.27-75.6 N, 162.5-161 W; keep a margin for a 100 km track.
ARCTIC_LAT = (74.5, 76.5)
ARCTIC_LON = (360 - 166.0, 360 - 157.0)


def crop_etopo5(source: Path, target: Path) -> None:
    ds = xr.open_dataset(source, decode_times=False)
    # The stored longitude axis drifts by up to 0.0033 deg from the true 5-minute grid.
    lon = np.arange(ds.sizes["ETOPO05_X"]) / 12.0
    ds = ds.assign_coords(ETOPO05_X=("ETOPO05_X", lon, ds["ETOPO05_X"].attrs))
    crop = ds.sel(ETOPO05_Y=slice(*ARCTIC_LAT), ETOPO05_X=slice(*ARCTIC_LON)).load()
    crop.attrs["tangraph_note"] = (
        "Cropped from Ferret's etopo5.cdf (Debian ferret-datasets); longitude axis rebuilt as "
        "arange(4320)/12 degrees east. ROSE is elevation (positive up), metres."
    )
    crop.to_netcdf(target)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--wheels", type=Path, required=True, help="folder of unpacked wheels")
    args = parser.parse_args()
    copies = {
        "anuga/parallel/data/merimbula_10785_1.tsh": "merimbula_10785_1.tsh",
        "lidar/data/dem.tif": "lidar_dem.tif",
        "isobath/sample.nc": "isobath_arabian_sea.nc",
    }
    for source, target in copies.items():
        shutil.copyfile(args.wheels / source, HERE / target)
    import matplotlib.cbook

    shutil.copyfile(matplotlib.cbook.get_sample_data("topobathy.npz", asfileobj=False),
                    HERE / "topobathy_vancouver.npz")
    crop_etopo5(ETOPO5, HERE / "etopo5_arctic.nc")


if __name__ == "__main__":
    main()
