"""Closed-form complexity counts N_LMIVAR of SPEC §8 (the paper's (59), (62), (63)).

These are formulas only; :meth:`sospoly.certificates.program.SOSProgram.n_lmivar` counts the
assembled program, and the tests check that both agree.
"""
from __future__ import annotations

from collections import Counter

from ..algebra.basis import sigma, tau

__all__ = ["n_lmivar_formula"]


def n_lmivar_formula(nvars: int, delta: int, eq_degrees=(), ineq_degrees=(), free_q_degree: int | None = None) -> int:
    """1 (for c) + tau(delta) + sum_k sigma(delta - deg g_k) + sum_k sigma(d_k)(sigma(d_k)+1)/2.

    d_k = floor((delta - deg h_k)/2).  With ``free_q_degree`` (the degree of a free
    SOS q), its Gram entries replace the scalar c in the count (c is then the
    bisection parameter, not a variable).
    """
    n = 1 + tau(nvars, delta)
    # counted per distinct degree: a Corollary 1 program at N = 400 views lists 79,800 equal degrees
    n += sum(k * sigma(nvars, delta - d) for d, k in Counter(eq_degrees).items())
    for d, k in Counter(ineq_degrees).items():
        s = sigma(nvars, (delta - d) // 2)
        n += k * (s * (s + 1) // 2)
    if free_q_degree is not None:
        s = sigma(nvars, free_q_degree // 2)
        n += s * (s + 1) // 2 - 1
    return n


def n_lmivar_cliques(clique_sizes, parents, overlaps, delta: int, eq_supports=(), ineq_sides=()) -> int:
    """Closed form of N_LMIVAR for a clique-wise certificate (no dense block) over a clique tree with
    the running-intersection property (:func:`sospoly.certificates.sparsity.clique_tree`).

    u's blocks have sides sigma(c_k, delta/2); the distinct monomials of u are those supported in some
    clique, counted exactly by the tree: sum_k sigma(c_k, delta) - sum_{k with a parent} sigma(o_k, delta),
    o_k = |C_k cap C_parent(k)| (a monomial supported in C_k and in an earlier clique is supported in
    C_k cap C_parent(k) by the running intersection).  So

        N_LMIVAR = 1 + sum_k L(sigma(c_k, delta/2)) - (#distinct monomials) + sum_k |supp r_k| + sum_k L(s_k),

    L(s) = s (s + 1) / 2; ``eq_supports`` the sizes of the multipliers r_k, ``ineq_sides`` the Gram
    sides of the s_k."""
    def L(s):
        return s * (s + 1) // 2

    pairs = sum(L(sigma(c, delta // 2)) for c in clique_sizes)
    monos = sum(sigma(c, delta) for c in clique_sizes)
    monos -= sum(sigma(o, delta) for o, p in zip(overlaps, parents) if p >= 0)
    return 1 + pairs - monos + sum(int(k) for k in eq_supports) + sum(L(int(s)) for s in ineq_sides)


def n_lmivar_shape(shape) -> int:
    """N_LMIVAR of a certificate shape (fixed q), counted from its bases: 1 + the Gram pairs of u's
    blocks - the distinct monomials they span + the free coefficients + the s_k Gram entries."""
    from ..algebra.basis import GramBlocks

    blocks = GramBlocks.of(list(shape.u_bases))
    s_entries = sum(b.shape[0] * (b.shape[0] + 1) // 2 for b in shape.s_bases)
    return 1 + blocks.n_pairs - blocks.n_products + shape.n_free() + s_entries


__all__ += ["n_lmivar_cliques", "n_lmivar_shape"]
