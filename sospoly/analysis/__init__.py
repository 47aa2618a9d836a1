"""Reading a solved certificate: minimiser extraction (:mod:`.extraction`, :mod:`.sparse_extraction`),
certification by verification of quadratic programs (:mod:`.verify`), complexity counts (:mod:`.complexity`) and
the feasible candidates of :func:`sospoly.minimize` (:mod:`.candidates`)."""

# The package face: every public name of the modules below, imported on first use (PEP 562), so
# importing the package costs nothing and creates no import cycle.  Callers outside sospoly import
# from ``sospoly.analysis``, never from its modules.
import importlib as _importlib

_MODULES = ('extraction', 'sparse_extraction', 'term_extraction', 'moments', 'verify', 'verify_sparse',
            'banded', 'rigor', 'proof', 'recession', 'complexity', 'candidates')


def _index() -> dict:
    out = {}
    for m in _MODULES:
        mod = _importlib.import_module(f"sospoly.analysis.{m}")
        for name in getattr(mod, "__all__", ()):
            out.setdefault(name, mod)
    return out


def __getattr__(name: str):
    if name.startswith("__"):
        raise AttributeError(name)
    mod = _index().get(name)
    if mod is None:
        raise AttributeError(f"module 'sospoly.analysis' has no attribute {name!r}")
    value = globals()[name] = getattr(mod, name)     # resolved once
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(_index()))
