"""Solving conic problems: back-ends (:mod:`.backends`: Clarabel, cvxpy, the batched interior-point method of
:mod:`.ipm`), solve-and-check (:mod:`.solve`), compiled structures solved (:mod:`.compiled_solve`), GEVP
bisection (:mod:`.gevp`) and BLAS threading (:mod:`.blas`)."""

# The package face: every public name of the modules below, imported on first use (PEP 562), so
# importing the package costs nothing and creates no import cycle.  Callers outside sospoly import
# from ``sospoly.solvers``, never from its modules.
import importlib as _importlib

_MODULES = ('backends', 'solve', 'compiled_solve', 'lower_bound', 'gevp', 'blas', 'stacked_conic')


def _index() -> dict:
    out = {}
    for m in _MODULES:
        mod = _importlib.import_module(f"sospoly.solvers.{m}")
        for name in getattr(mod, "__all__", ()):
            out.setdefault(name, mod)
    return out


def __getattr__(name: str):
    if name.startswith("__"):
        raise AttributeError(name)
    mod = _index().get(name)
    if mod is None:
        raise AttributeError(f"module 'sospoly.solvers' has no attribute {name!r}")
    value = globals()[name] = getattr(mod, name)     # resolved once
    return value


def __dir__() -> list:
    return sorted(set(globals()) | set(_index()))
