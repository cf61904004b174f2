"""The shipped catalogue: every map loads, from the files as shipped, with sane figures."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import catalogue, list_maps, load, load_any, to_lonlat

# name: (a point inside the map's area (lat, lon), depth range it must fall within)
REAL = {
    "merimbula": ((-36.90, 149.90), (-2.0, 15.0)),
    "lidar-dem": ((46.5, -93.9), (20.0, 60.0)),
    "arabian-sea": ((14.0, 71.5), (-3000.0, 5500.0)),
    "vancouver": ((49.0, -124.0), (-2500.0, 2500.0)),
    "arctic-etopo5": ((75.5, -161.5), (0.0, 4000.0)),
}


def test_catalogue_lists_real_and_synthetic_maps_with_provenance():
    assert set(REAL) | {"han2020", "polar500"} == set(list_maps())
    for entry in catalogue().values():
        assert entry.licence and entry.source and entry.title
        assert (entry.file is None) != (entry.generator is None)


# arabian-sea is 13 degrees wide (0.64 % scale error on one transverse Mercator): its catalogue
# entry accepts that (read option max_scale_error = 0.007)
@pytest.mark.parametrize("name", list(REAL))
def test_real_maps_load_in_place(name):
    (lat, lon), (lo, hi) = REAL[name]
    m = load(name)
    assert m.name == name
    assert lo <= np.nanmin(m.depth) and np.nanmax(m.depth) <= hi
    n_lo, n_hi, e_lo, e_hi = m.extent
    c_lat, c_lon = to_lonlat(m, 0.5 * (n_lo + n_hi), 0.5 * (e_lo + e_hi))
    assert abs(c_lat - lat) < 1.0 and abs(c_lon - lon) < 1.5


def test_lidar_dem_is_rebased_and_merimbula_is_a_lake():
    assert np.nanmin(load("lidar-dem").depth) == pytest.approx(20.0)
    merimbula = load("merimbula")
    assert merimbula.cell_size == (10.0, 10.0)
    assert merimbula.crs == "EPSG:32755"
    assert 0.15 < merimbula.valid_fraction < 0.5


def test_synthetic_entries_are_seeded_and_have_the_papers_cells():
    han = load("han2020")
    assert han.shape == (1000, 1000) and han.cell_size == (5.0, 5.0)
    assert load("polar500").cell_size == (500.0, 500.0)
    assert load("han2020") is han  # maps are immutable: loaded once


def test_unknown_name_lists_the_known_ones(tmp_path):
    with pytest.raises(TangraphError, match="no map named 'atlantis'.*merimbula"):
        load("atlantis")
    with pytest.raises(TangraphError, match="neither a catalogue map"):
        load_any("atlantis")
    with pytest.raises(FileNotFoundError):
        load_any(tmp_path / "atlantis.nc")


def test_a_private_catalogue_adds_to_the_shipped_maps(tmp_path, monkeypatch):
    from tangraph.maps import catalogue, write_map
    from tangraph.maps.synthetic import fractal

    write_map(fractal((20, 20), 5.0, rng=np.random.default_rng(1)), tmp_path / "mine.nc")
    (tmp_path / "catalogue.toml").write_text(
        '[my-lake]\ntitle = "a private map"\nfile = "mine.nc"\nlicence = "mine"\nsource = "test"\n'
    )
    monkeypatch.setenv("TANGRAPH_MAPS", str(tmp_path))
    catalogue.cache_clear()
    try:
        names = list(catalogue())
        assert "my-lake" in names and "merimbula" in names
        assert load_any("my-lake").shape == (20, 20)
        (tmp_path / "catalogue.toml").write_text(
            '[merimbula]\ntitle = "x"\nfile = "mine.nc"\nlicence = "x"\nsource = "x"\n'
        )
        catalogue.cache_clear()
        with pytest.raises(TangraphError, match="map 'merimbula' is also in"):
            catalogue()
    finally:
        monkeypatch.delenv("TANGRAPH_MAPS")
        catalogue.cache_clear()


def test_a_catalogue_map_takes_a_cell_but_not_file_options():
    m = load_any("merimbula", cell=20.0)
    assert m.cell_size == (20.0, 20.0) and m.name == "merimbula"
    with pytest.raises(TangraphError, match="sign does not apply to the catalogue map 'merimbula'"):
        load_any("merimbula", sign="depth")
