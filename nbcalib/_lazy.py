"""Packages whose public names load on first use (``import nbcalib.matching`` stays cheap)."""

from __future__ import annotations

import importlib
from collections.abc import Callable

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, modules: dict[str, tuple[str, ...]]
) -> tuple[Callable, Callable, list[str]]:
    """``__getattr__``, ``__dir__`` and ``__all__`` for a package's lazily imported names.

    Parameters
    ----------
    package : str
        The package (``"nbcalib.matching"``).
    modules : dict of str to tuple of str
        Submodule -> the public names it provides to the package.

    Examples
    --------
    >>> __getattr__, __dir__, __all__ = lazy_exports(
    ...     "nbcalib.report", {"quality": ("assess",)}
    ... )  # doctest: +SKIP
    """
    where = {name: module for module, names in modules.items() for name in names}
    names = sorted(where)

    def __getattr__(name: str):
        if name in where:
            return getattr(importlib.import_module(f"{package}.{where[name]}"), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return names

    return __getattr__, __dir__, names
