"""Solving conic problems: back-ends (:mod:`.backends`: Clarabel, cvxpy, the batched interior-point method of
:mod:`.ipm`), solve-and-check (:mod:`.solve`), GEVP bisection (:mod:`.gevp`) and BLAS threading (:mod:`.blas`)."""
