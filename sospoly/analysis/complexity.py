"""Closed-form complexity counts N_LMIVAR of SPEC §8 (the paper's (59), (62), (63)).

These are formulas only; :meth:`sospoly.certificates.program.SOSProgram.n_lmivar` counts the
assembled program, and the tests check that both agree.
"""
from __future__ import annotations

from ..algebra.basis import sigma, tau

__all__ = ["n_lmivar_formula"]


def n_lmivar_formula(nvars: int, delta: int, eq_degrees=(), ineq_degrees=(), free_q_degree: int | None = None) -> int:
    """1 (for c) + tau(delta) + sum_k sigma(delta - deg g_k) + sum_k sigma(d_k)(sigma(d_k)+1)/2.

    d_k = floor((delta - deg h_k)/2).  With ``free_q_degree`` (the degree of a free
    SOS q), its Gram entries replace the scalar c in the count (c is then the
    bisection parameter, not a variable).
    """
    n = 1 + tau(nvars, delta)
    n += sum(sigma(nvars, delta - d) for d in eq_degrees)
    for d in ineq_degrees:
        s = sigma(nvars, (delta - d) // 2)
        n += s * (s + 1) // 2
    if free_q_degree is not None:
        s = sigma(nvars, free_q_degree // 2)
        n += s * (s + 1) // 2 - 1
    return n
