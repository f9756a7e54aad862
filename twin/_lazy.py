"""Lazy package faces (PEP 562): a face lists its public names and the module of each; a name's
module is imported on first use, so ``import twin`` (or ``from twin import Blend``) costs only
what is used. ``grindtwin steady --surrogate`` and ``grindtwin --help`` then start without
CasADi, SciPy, pandas or scikit-learn (benchmarks/cli_startup.py measures it)."""

from __future__ import annotations

import sys
from importlib import import_module


def lazy_face(package: str, api: dict[str, str]):
    """``(__getattr__, __dir__)`` for the package ``package``: ``api`` maps a public name to the
    (relative) module that defines it; a submodule (``twin.ore``) is imported when asked for."""

    def __getattr__(name: str):
        if name in api:
            value = getattr(import_module(api[name], package), name)
            setattr(sys.modules[package], name, value)  # next time a plain attribute
            return value
        if not name.startswith("__"):
            try:
                return import_module(f".{name}", package)
            except ModuleNotFoundError as exc:
                if exc.name != f"{package}.{name}":
                    raise
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__():
        return sorted(set(vars(sys.modules[package])) | set(api))

    return __getattr__, __dir__
