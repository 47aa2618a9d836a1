"""Package faces: a sub-package exports its modules' public names, imported on first use (PEP 562).

Importing the package costs nothing and creates no import cycle; callers outside sospoly import from
``sospoly.analysis`` / ``sospoly.solvers``, never from their modules (tests/test_architecture.py)."""
from __future__ import annotations

import importlib

__all__ = ["lazy_face"]


def lazy_face(package: str, modules: tuple, namespace: dict):
    """``(__getattr__, __dir__)`` of ``package`` exporting every name in the ``__all__`` of its ``modules``
    (the first module that lists a name wins); a resolved name is stored in ``namespace`` (the package's
    globals), so each is looked up once."""

    def index() -> dict:
        out = {}
        for m in modules:
            mod = importlib.import_module(f"{package}.{m}")
            for name in getattr(mod, "__all__", ()):
                out.setdefault(name, mod)
        return out

    def __getattr__(name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        mod = index().get(name)
        if mod is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = namespace[name] = getattr(mod, name)
        return value

    def __dir__() -> list:
        return sorted(set(namespace) | set(index()))

    return __getattr__, __dir__
