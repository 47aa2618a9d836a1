"""The optional cvxpy back-end's availability checks (kept apart from :mod:`sospoly.solvers.backends`, which
re-exports them): importing cvxpy costs seconds, so nothing here runs before a cvxpy back-end is asked for."""
from __future__ import annotations

__all__ = ["cvxpy_available", "import_cvxpy", "check_cvxpy_solver"]


def cvxpy_available() -> bool:
    """Whether the optional cvxpy back-end can be imported (``pip install sospoly-tritools[cvxpy]``)."""
    import importlib.util

    return importlib.util.find_spec("cvxpy") is not None


def import_cvxpy():
    """``import cvxpy``, or an ImportError saying how to install the optional back-end."""
    try:
        import cvxpy
    except ImportError as exc:
        raise ImportError("the 'cvxpy' back-end needs cvxpy, an optional dependency: "
                          "pip install 'sospoly-tritools[cvxpy]' (or use backend='clarabel')") from exc
    return cvxpy


def check_cvxpy_solver(solver: str | None) -> None:
    """ValueError for a solver name cvxpy does not know, ImportError for a known one not installed."""
    cp = import_cvxpy()
    if solver is None:
        return
    import cvxpy.settings

    if solver not in cvxpy.settings.SOLVERS:
        raise ValueError(f"unknown cvxpy solver {solver!r} in backend 'cvxpy:{solver}': cvxpy knows "
                         f"{', '.join(cvxpy.settings.SOLVERS)}")
    if solver not in cp.installed_solvers():
        raise ImportError(f"cvxpy solver {solver!r} (backend 'cvxpy:{solver}') is not installed; installed: "
                          f"{', '.join(cp.installed_solvers())}")
