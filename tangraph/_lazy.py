"""Names a package imports only when first used (PEP 562), so that ``import tangraph`` stays fast."""

from __future__ import annotations

import importlib
from collections.abc import Callable


def lazy_names(namespace: dict, where: dict[str, str]) -> tuple[Callable, Callable]:
    """The ``__getattr__`` and ``__dir__`` of a package whose names ``where`` (name -> module)
    are imported when first asked for and then kept in ``namespace`` (its ``globals()``)."""
    package = namespace["__name__"]

    def __getattr__(name: str):
        if name in where:
            value = getattr(importlib.import_module(where[name]), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(where))

    return __getattr__, __dir__
