"""Wheel build hook: the studies (experiments/) go into the wheel without their results.

Each study's committed tables and figures (``experiments/*/results``) belong to the repository;
an installed study writes its results to the folder its user names (``--out``).
"""

from __future__ import annotations

from pathlib import Path

from hatchling.builders.hooks.plugin.interface import BuildHookInterface


class CustomBuildHook(BuildHookInterface):
    def initialize(self, version: str, build_data: dict) -> None:
        root = Path(self.root) / "experiments"
        for path in sorted(root.rglob("*")):
            relative = path.relative_to(root)
            if not path.is_file() or "results" in relative.parts or "__pycache__" in relative.parts:
                continue
            build_data["force_include"][str(path)] = f"tangraph/_experiments/{relative.as_posix()}"
