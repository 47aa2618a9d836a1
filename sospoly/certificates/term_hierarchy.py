"""The term-sparsity (TSSOS) hierarchy as certificate shapes, and its levels for :func:`sospoly.minimize`.

A level is named by a *kind* string: ``"term"`` (one step, chordal completion) or
``"term:<completion>:<steps>"`` with completion ``chordal`` or ``block``
(:data:`~sospoly.certificates.sparsity.TERM_COMPLETIONS`).  The shape of a level: u's dense basis,
reduced to the Newton polytope's half (Reznick 1978) for an unconstrained program, split into the
blocks of :func:`~sospoly.certificates.sparsity.term_sparsity_iterate` over the support of u
(f, the constraints, the constant); multipliers stay dense.

Strength: every level is a restriction of the dense certificate, so every bound is valid and at most
the dense bound; the levels of one completion grow monotonically with ``steps``.  With the
``block`` completion the stable level of an unconstrained program gives the dense bound (its blocks
are the sign-symmetry blocks: Wang, Magron & Lasserre, "TSSOS", SIAM J. Optim. 2021, Thm 3.3);
the ``chordal`` completion is cheaper and may stop below it (the SumOfSquares.jl term-sparsity
tutorial polynomial: -0.00355 against the dense 0).

:func:`term_levels` lists the distinct levels in the order ``minimize(sparsity="term")`` tries them:
chordal steps 1, 2, ... to stability, then block steps 1, 2, ... to stability, each level kept only
when its blocks differ from every earlier level's, sorted by the number of Gram entries (the solver's
cost; ties keep that order).  The last block level is always among them, so the walk ends at the
dense bound for an unconstrained program.
"""
from __future__ import annotations

import numpy as np

from ..budget import check_deadline
from .shape import CertificateShape, Sparsity, u_support_of, dense_shape
from .sparsity import TERM_COMPLETIONS, newton_reduce, term_sparsity_iterate

__all__ = ["parse_term_kind", "term_kind", "term_level_shape", "term_levels", "term_level_costs", "cheap_term_level",
           "newton_smaller", "MAX_TERM_STEPS"]

#: the hierarchy of one completion stops after this many steps even when not stable
MAX_TERM_STEPS = 6


def term_kind(completion: str, steps: int) -> str:
    """The kind string of a level (``"term"`` for chordal, one step)."""
    return "term" if (completion, steps) == ("chordal", 1) else f"term:{completion}:{int(steps)}"


def parse_term_kind(kind) -> tuple[str, int] | None:
    """(completion, steps) of a term kind string, None for any other value (ValueError for a malformed one)."""
    if not isinstance(kind, str) or not kind.startswith("term"):
        return None
    if kind == "term":
        return "chordal", 1
    parts = kind.split(":")
    if len(parts) != 3 or parts[1] not in TERM_COMPLETIONS or not parts[2].isdigit() or int(parts[2]) < 1:
        raise ValueError(f"a term-sparsity kind is 'term' or 'term:<chordal|block>:<steps >= 1>', got {kind!r}")
    return parts[1], int(parts[2])


def _level(u_support: np.ndarray, basis: np.ndarray, completion: str, steps: int):
    return term_sparsity_iterate(u_support, basis, steps, completion=completion)


def _base(f_support, eq_supports, ineq_supports, degree: int, max_gram_side, u_support=None):
    f_support = np.asarray(f_support, dtype=np.int64)
    n = f_support.shape[1]
    degs = [[int(np.asarray(E).sum(axis=1).max(initial=0)) for E in S] for S in (eq_supports, ineq_supports)]
    dense = dense_shape(n, degree, degs[0], degs[1], max_gram_side)
    u_support = u_support_of(f_support, eq_supports, ineq_supports, n) if u_support is None else u_support
    basis = dense.u_bases[0]
    if not len(eq_supports) and not len(ineq_supports):
        basis = newton_reduce(u_support, basis)        # Reznick: unconstrained u = f - c
    return dense, u_support, basis


def term_level_shape(f_support, eq_supports, ineq_supports, degree: int, kind: str = "term", *,
                     max_gram_side: int | None = None, u_support=None) -> CertificateShape:
    """The shape of the level ``kind`` (module docstring); ``u_support`` overrides the support of u
    (e.g. supp(q f) for a user multiplier q)."""
    completion, steps = parse_term_kind(kind)
    dense, u_support, basis = _base(f_support, eq_supports, ineq_supports, degree, max_gram_side, u_support)
    ts = _level(u_support, basis, completion, steps)
    return CertificateShape(Sparsity.TERM, tuple(basis[b] for b in ts.blocks), dense.r_supports, dense.s_bases)


def term_levels(f_support, eq_supports, ineq_supports, degree: int, *, max_gram_side: int | None = None,
                u_support=None) -> list[str]:
    """The distinct levels of the hierarchy, cheapest first (module docstring)."""
    return [kind for kind, _ in term_level_costs(f_support, eq_supports, ineq_supports, degree,
                                                 max_gram_side=max_gram_side, u_support=u_support)]


def cheap_term_level(f_support, eq_supports, ineq_supports, degree: int, fraction: float = 0.75) -> str | None:
    """The cheapest level when its Gram entries are below ``fraction`` of the dense basis' (else None): the
    level ``sparsity="auto"`` tries before the dense certificate."""
    f_support = np.asarray(f_support, dtype=np.int64)
    s = dense_shape(f_support.shape[1], degree).u_bases[0].shape[0]
    levels = term_level_costs(f_support, eq_supports, ineq_supports, degree)
    return levels[0][0] if levels and levels[0][1] < fraction * s * (s + 1) // 2 else None


def term_level_costs(f_support, eq_supports, ineq_supports, degree: int, *, max_gram_side: int | None = None,
                     u_support=None) -> list[tuple[str, int]]:
    """(kind, Gram entries) of the distinct levels, cheapest first (module docstring)."""
    _, u_support, basis = _base(f_support, eq_supports, ineq_supports, degree, max_gram_side, u_support)
    seen, out = set(), []
    for completion in TERM_COMPLETIONS:
        for steps in range(1, MAX_TERM_STEPS + 1):
            check_deadline("choosing the term-sparsity level")       # (graph work: review 38a M3)
            ts = _level(u_support, basis, completion, steps)
            key = tuple(tuple(b.tolist()) for b in ts.blocks)
            if key not in seen:
                seen.add(key)
                out.append((sum(b.size * (b.size + 1) // 2 for b in ts.blocks), len(out),
                            term_kind(completion, ts.iterations)))
            if ts.stable or ts.iterations < steps:
                break
    return [(kind, cost) for cost, _, kind in sorted(out)]


def newton_smaller(f_support, degree: int) -> bool:
    """Is the Newton-polytope basis of an unconstrained u = f - c smaller than the dense one at ``degree``?"""
    from .shape import newton_shape

    f_support = np.asarray(f_support, dtype=np.int64)
    n = f_support.shape[1]
    from ..algebra.basis import sigma

    return newton_shape(f_support, degree).u_bases[0].shape[0] < sigma(n, degree // 2)
