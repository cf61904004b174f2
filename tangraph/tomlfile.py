"""Settings files: one TOML table read with the errors every settings file gives."""

from __future__ import annotations

import os
import tomllib
from pathlib import Path

from tangraph.errors import TangraphError

__all__ = ["read_table"]


def read_table(path: str | os.PathLike, table: str, what: str) -> dict:
    """The fields of a TOML file of settings: at its top level, or in its ``[table]`` (then no
    other key may stand beside it). ``what`` names the file in errors ("graph config file").
    """
    path = Path(path)
    if not path.is_file():
        raise TangraphError(f"{what} {path} does not exist")
    try:
        with open(path, "rb") as f:
            content = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise TangraphError(f"{path}: not valid TOML ({exc})") from None
    if table in content:
        extra = sorted(set(content) - {table})
        if extra:
            raise TangraphError(f"{path}: keys outside [{table}]: {', '.join(extra)}")
        content = content[table]
    return content
