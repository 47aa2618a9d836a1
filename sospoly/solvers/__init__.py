"""Solving conic problems: back-ends (:mod:`.backends`: Clarabel, cvxpy, the batched interior-point method of
:mod:`.ipm`), solve-and-check (:mod:`.solve`), compiled structures solved (:mod:`.compiled_solve`), GEVP
bisection (:mod:`.gevp`) and BLAS threading (:mod:`.blas`)."""

# The package face (:mod:`sospoly.faces`): callers outside sospoly import from ``sospoly.solvers``.
from ..faces import lazy_face

_MODULES = ('backends', 'solve', 'compiled_solve', 'lower_bound', 'gevp', 'blas', 'stacked_conic', 'level')

__getattr__, __dir__ = lazy_face(__name__, _MODULES, globals())
