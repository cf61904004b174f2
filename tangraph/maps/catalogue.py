"""The shipped map catalogue: real grids from packages and seeded synthetic charts, by name.

The files and ``catalogue.toml`` live in the repository's top-level ``maps/`` folder (packed into
the wheel as ``tangraph/_catalogue``); ``TANGRAPH_MAPS`` points elsewhere if set.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.io import read_map

__all__ = ["CatalogueEntry", "catalogue", "catalogue_path", "list_maps", "load", "load_any"]


@dataclasses.dataclass(frozen=True)
class CatalogueEntry:
    """One map of the catalogue (see ``maps/catalogue.toml``)."""

    name: str
    title: str
    licence: str
    source: str
    file: str | None = None
    generator: str | None = None
    seed: int | None = None
    read: dict[str, Any] = dataclasses.field(default_factory=dict)
    shallowest: float | None = None
    folder: str = ""  #: the folder of its catalogue.toml (where ``file`` lies)


def catalogue_path() -> Path:
    """The folder holding the shipped catalogue's files."""
    here = Path(__file__).resolve().parent
    candidates = [here.parent / "_catalogue", here.parents[1] / "maps"]
    for folder in candidates:
        if (folder / "catalogue.toml").is_file():
            return folder
    raise TangraphError(
        f"the map catalogue is missing (looked for catalogue.toml in {[str(c) for c in candidates]})"
    )


@functools.cache
def catalogue() -> dict[str, CatalogueEntry]:
    """All catalogue entries by name: the shipped maps, and those of a private catalogue (a
    folder with its own ``catalogue.toml``) named by the environment variable
    ``TANGRAPH_MAPS``, which add to them; a private map may not take a shipped map's name."""
    folders = [catalogue_path()]
    if os.environ.get("TANGRAPH_MAPS"):
        private = Path(os.environ["TANGRAPH_MAPS"])
        if not (private / "catalogue.toml").is_file():
            raise TangraphError(f"TANGRAPH_MAPS={private}: no catalogue.toml in that folder")
        folders.append(private)
    entries: dict[str, CatalogueEntry] = {}
    for folder in folders:
        path = folder / "catalogue.toml"
        try:
            with open(path, "rb") as f:
                table = tomllib.load(f)
        except tomllib.TOMLDecodeError as exc:
            raise TangraphError(f"{path}: not valid TOML ({exc})") from None
        for name, fields in table.items():
            if name in entries:
                raise TangraphError(
                    f"{path}: map {name!r} is also in {Path(entries[name].folder) / 'catalogue.toml'}; "
                    "give the private one another name"
                )
            try:
                entries[name] = CatalogueEntry(name=name, folder=str(folder), **fields)
            except TypeError as exc:
                raise TangraphError(f"{path}: map {name!r}: {exc}") from None
    return entries


def list_maps() -> list[str]:
    """Names of the maps in the catalogue."""
    return list(catalogue())


def _entry(name: str) -> CatalogueEntry:
    entries = catalogue()
    if name not in entries:
        raise TangraphError(f"no map named {name!r} in the catalogue; known maps: {', '.join(entries)}")
    return entries[name]


@functools.cache
def load(name: str) -> BathymetryMap:
    """A catalogue map by name (maps are immutable, so each is read once per process).

    Examples
    --------
    >>> from tangraph.maps import load
    >>> m = load("vancouver")
    >>> m.name
    'vancouver'
    """
    entry = _entry(name)
    if entry.generator is not None:
        module, function = entry.generator.split(":")
        generate = getattr(importlib.import_module(module), function)
        bathymetry = generate(rng=np.random.default_rng(entry.seed))
    else:
        bathymetry = read_map(Path(entry.folder) / str(entry.file), name=name, **entry.read)
    if entry.shallowest is not None:
        shift = entry.shallowest - float(np.nanmin(bathymetry.depth))
        bathymetry = bathymetry.replace(depth=bathymetry.depth + shift)
    return bathymetry.replace(name=name)


def load_any(name_or_path: str | os.PathLike, **read_options) -> BathymetryMap:
    """A catalogue map if ``name_or_path`` is a catalogue name, else :func:`read_map` of a file.

    A catalogue map takes ``cell`` (it is resampled); the options that say how to read a file
    (``sign``, ``variable``, ``crs``, ...) do not apply to it and are refused.
    """
    if str(name_or_path) in catalogue():
        options = {k: v for k, v in read_options.items() if v is not None}
        cell = options.pop("cell", None)
        if options:
            raise TangraphError(
                f"{', '.join(sorted(options))} {'does' if len(options) == 1 else 'do'} not apply to the "
                f"catalogue map {str(name_or_path)!r}: it is read as its catalogue entry says"
            )
        bathymetry = load(str(name_or_path))
        return bathymetry if cell is None else bathymetry.resample(float(cell))
    path = Path(name_or_path)
    if not path.exists() and path.suffix == "":
        raise TangraphError(
            f"{str(name_or_path)!r} is neither a catalogue map ({', '.join(catalogue())}) nor a file"
        )
    return read_map(path, **read_options)
