"""What a Positivstellensatz solve may claim: a level, "the set is empty", "no certificate" -- each only where proven.

A solver's certificate u = q (f - c) + sum r_k g_k - sum s_k h_k = sum_j b_j^T G_j b_j is accepted numerically when
lambda_min(G_j) >= -psd_margin max|G_j|.  That defect eps_j changes the *level* by up to
eps_j ||b_j(v*)||^2 / q(v*) at a minimiser v*, which grows like ||v*||^(deg f): at f = x^2 - 2e4 x the accepted
certificate's level lay 7.2e3 above the minimum -1e8 (review 26a F5), and a bisection that climbs to the edge of
the margin (the GEVP, F2) overshoots by far more.  No margin on the Gram matrices alone can be right at every
scale, so the claims are proven instead, by :func:`sospoly.analysis.proof.global_psatz_bound` (the shifted
certificate: the level lowered by m, the Gram matrices shifted and projected onto the exact identities, every
rounding bounded and absorbed, q proven positive for every v):

* :func:`proven_level` -- the level of a fixed-q solve: OPTIMAL with ``lower_bound = c* - m`` when it is proven with
  m <= 1e-7 max(scale, |c*|) (:data:`~sospoly.analysis.proof.GLOBAL_MARGINS`, inside the gap tolerance);
  INACCURATE with the weaker proven ``c* - m`` when only a larger margin proves it
  (:data:`~sospoly.analysis.proof.WEAK_MARGINS`); else UNPROVEN with no bound.  ``scale`` is max |coef f|, the
  problem's own scale.  The solver's numerical c* stays available as ``relaxation``.
* :func:`proven_empty` -- an unboundedness ray (c grows along it) is a certificate that the set is empty:
  with f's coefficients set to 0 the ray d is a certificate  q (0 - c_d) + r_d^T g - s_d^T h = b^T G_d b,  G_d the
  ray's Gram matrices, i.e. 0 >= c_d on the feasible set with c_d > 0.  It is proven the same way (the f = 0
  instance at level c_d, lowered by m < c_d; or, where the constraints bound every feasible point in a box, by
  :func:`~sospoly.analysis.rigor.rigorous_psatz_bound` on it, which also charges the inexact multipliers of the
  ray); otherwise the status is NUMERICAL_ERROR (UNPROVEN where q is not proven positive) and nothing is claimed.
* :func:`balanced_recheck` -- "no certificate at this degree" (INFEASIBLE) rests on a Farkas certificate checked
  against its own terms, which cannot see an ill-conditioned dual: at f = x^2 - 2e6 x (q = 1) a moment matrix with
  L(1) ~ 0 and L(x) ~ 1e-6 violates PSD-ness by ~1e-12 and "proves" L(f) < 0, although (x - 1e6)^2 is a
  certificate (review 26a F5).  The claim is therefore re-decided on the *same* program written in balanced
  variables v = 2^k w (:func:`sospoly.scaling.balancing`; f, the constraints and q(2^k w) divided by powers of
  two: every step exact, so a certificate of one is a certificate of the other): INFEASIBLE is kept only where the
  balanced program says so too (or the data is balanced already); where the balanced program is solved, its
  proven bound (times f's divisor) is reported with status INACCURATE and no certificate (the certificate is the
  balanced program's); an unproven ray is re-decided the same way.  (With ``prove=False`` the solves make no
  further solve: the caller, who proves its own bounds, judges the solver's checked INFEASIBLE.)
  (:func:`sospoly.solvers.rays.check_unbounded_ray` measures the ray against its own terms: along a near-ray of
  min x^2 s.t. x = 1e6 the violation is ~1e-6 of them, review 26a F1.)
"""
from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

from ..status import SolveStatus
from .solve import LowerBound, ProgramSolution

__all__ = ["PsatzBound", "proven_level", "proven_bound", "proven_empty", "balanced_recheck", "as_certificate_data",
           "data_scale"]


@dataclass(frozen=True)
class PsatzBound(LowerBound):
    """A :class:`~sospoly.solvers.solve.LowerBound` whose ``lower_bound`` is proven (module docstring), with the
    solver's numerical level ``relaxation`` (c*, not proven; None where the solve gave none)."""
    relaxation: float | None = None


def as_certificate_data(psatz, structure=None, theta=None):
    """What the proofs read -- ``structure``, ``theta``, ``ineq`` -- of a PsatzProblem, a compiled instance, or a
    structure and theta."""
    if psatz is not None and hasattr(psatz, "ineq"):
        return psatz
    structure = psatz.structure if structure is None else structure
    theta = np.asarray(psatz.theta if theta is None else theta, float)
    slots = structure.slots
    ineq = slots.ineq_polynomials(theta) if slots.n_ineq else ()
    return SimpleNamespace(structure=structure, theta=theta, ineq=ineq)


def data_scale(data) -> float:
    """max |coef f| (the problem's own scale of the level), 1 for f = 0."""
    off = data.structure.slots.offsets
    th = np.abs(np.asarray(data.theta, float)[off[0]:off[1]])
    top = float(th.max()) if th.size else 0.0
    return top if top > 0 and np.isfinite(top) else 1.0


def proven_level(data, lb: LowerBound, tolerances=None, deadline=None) -> PsatzBound:
    """The claim of a fixed- or free-q solve's level (module docstring); other statuses pass through unchanged.

    The proven bound is the best of the shifted certificate (valid for every v) and, where the feasible set or a
    sublevel set of f lies in a box, :func:`~sospoly.analysis.rigor.rigorous_psatz_bound` on that box (the box of
    the constraints, :func:`~sospoly.analysis.proof.constraint_box`; for an unconstrained f the sublevel box
    {f <= f(v^)} of :func:`~sospoly.analysis.proof.sublevel_box`, v^ the origin or the moment matrix's point,
    every point being feasible; where neither proves anything, the exact proof on a face of the PSD cone of
    :mod:`sospoly.analysis.exact_face`, small programs only).  The shifted certificate cannot move an equality
    multiplier: on the sphere, min v^T Q v s.t. ||v||^2 = 1, the Gram matrix is singular along a direction the
    lowered level does not reach, and only the box proves it.  OPTIMAL when the proven bound lies within the gap
    tolerance of c* (``tolerances.gap_tolerance(c*, scale)``), INACCURATE with the weaker proven bound otherwise,
    UNPROVEN without one."""
    from ..analysis.proof import WEAK_MARGINS, global_psatz_bound
    from ..tolerances import as_tolerances

    if isinstance(lb, PsatzBound) or lb.status != SolveStatus.OPTIMAL or lb.lower_bound is None \
            or lb.solution is None or not np.isfinite(lb.lower_bound):
        return _wrap(lb)
    tol = as_tolerances(tolerances)
    c, sol = float(lb.lower_bound), lb.solution
    scale = data_scale(data)
    near = tol.gap_tolerance_one(c, scale)
    best, how, why = proven_bound(data, sol, c, scale, near, deadline)
    if not np.isfinite(best) and why != _Q_NOT_POSITIVE:
        best = global_psatz_bound(data, sol, c, scale=scale, margins=WEAK_MARGINS, deadline=deadline).lower_bound
        how = "the shifted certificate at a larger margin"
    if not np.isfinite(best) and why != _Q_NOT_POSITIVE and not data.structure.free:
        # every Gram matrix on a singular face of the PSD cone (Rosenbrock's): the exact proof on that face, as
        # minimize's step 2 (small programs only)
        from ..analysis.exact_face import face_exact_check
        from ..analysis.proof import GLOBAL_MARGINS

        fc = face_exact_check(data, sol, c, [r * max(1.0, abs(c)) for r in GLOBAL_MARGINS + WEAK_MARGINS])
        if fc.ok:
            best, how = fc.level, f"in exact arithmetic on a face ({fc.message})"
    if not np.isfinite(best):
        return PsatzBound(SolveStatus.UNPROVEN, None, sol, lb.bracket,
                          f"the solver's level {c:.10g} is not proven a lower bound: {why}", relaxation=c)
    if best >= c - near:
        return PsatzBound(SolveStatus.OPTIMAL, best, sol, lb.bracket, lb.message, relaxation=c)
    return PsatzBound(SolveStatus.INACCURATE, best, sol, lb.bracket,
                      f"the solver's level {c:.10g} is proven only lowered by {c - best:.3g} ({how})", relaxation=c)


_Q_NOT_POSITIVE = "the multiplier q is not proven positive everywhere"


def proven_bound(data, sol, c: float, scale: float, near: float, deadline=None) -> tuple[float, str, str]:
    """(the best bound proven from the certificate ``sol`` at level c, or -inf; how; why not): the shifted
    certificate (every v), and where it proves less than c - ``near``, the rigorous bound on a box
    (:func:`proven_level`'s docstring)."""
    from ..analysis.proof import global_psatz_bound

    gb = global_psatz_bound(data, sol, c, scale=scale, deadline=deadline)
    best, how = gb.lower_bound, "for every v by the shifted certificate"
    if not best >= c - near:
        rb, where = _box_bound(data, sol, c)          # (q's lower bound on the box, for a q not proven positive too)
        if rb > best:
            best, how = rb, where
    return best, how, (gb.message if gb.q_min > 0 else _Q_NOT_POSITIVE)


def _box_bound(data, sol, c: float) -> tuple[float, str]:
    """(the rigorous bound on a box holding every feasible point or a minimiser, or -inf; which box)."""
    from ..analysis.proof import constraint_box, sublevel_box
    from ..analysis.rigor import rigorous_psatz_bound

    st = data.structure
    f, eq, ineq = st.slots.polynomials(data.theta)
    n = len(st.gens)
    if eq or ineq:
        box, where = constraint_box(eq, ineq, n), "on the box of the constraints"
    else:
        upper = min(float(v) for v in (f.evaluate(np.zeros(n)), _moment_value(st, f, sol)) if np.isfinite(v))
        box, where = sublevel_box(f, upper), f"on the box of the sublevel set f <= {upper:.6g}"
    if box is None:
        return -np.inf, ""
    return rigorous_psatz_bound(data, sol, c, box).lower_bound, where


def _ray_box_bound(zero, ray, c_d: float) -> float:
    """The rigorous bound of a ray's certificate (the f = 0 instance at level c_d) on the box of the constraints, a
    variable the constraints do not bound taken as 0 where the certificate does not involve it (no non-zero term,
    Gram entry or multiplier of a constraint holding it: the identity then holds for every value of it); -inf
    without such a box."""
    from ..analysis.proof import constraint_box
    from ..analysis.rigor import rigorous_psatz_bound, solution_at_level, u_terms

    st = zero.structure
    _, eq, ineq = st.slots.polynomials(zero.theta)
    r = constraint_box(eq, ineq, len(st.gens), partial=True)
    if not np.all(np.isfinite(r)):
        used = np.zeros(len(st.gens), bool)
        E, v = u_terms(st, zero.theta, solution_at_level(st, ray.x, c_d), c_d)
        used |= np.any(E[v != 0] > 0, axis=0)
        for name, blk in zip(st.u.block_names(), st.u.gram.blocks):
            G = np.asarray(ray.grams[name])
            rows = np.any(G != 0, axis=1)
            used |= np.any(blk.b[rows] > 0, axis=0)
        prog = st.program
        for k, p in enumerate(tuple(eq) + tuple(ineq)):
            name = f"r{k}" if k < len(eq) else f"s{k - len(eq)}"
            if np.any(ray.x[prog.block(name).slice] != 0):
                used |= np.any(p.exponents() > 0, axis=0) if p.terms else False
        r = np.where(np.isfinite(r) | used, r, 0.0)
    if not np.all(np.isfinite(r)):
        return -np.inf
    return float(rigorous_psatz_bound(zero, ray, c_d, r).lower_bound)


def _moment_value(structure, f, sol) -> float:
    """f at the point of u's moment matrix (its degree-1 moments over the constant's), NaN without one."""
    blocks = structure.u.gram.blocks
    M = sol.moments.get(structure.u.block_names()[0]) if sol.moments else None
    if M is None or not blocks:
        return np.nan
    B = blocks[0].b
    n = B.shape[1]
    deg = B.sum(axis=1)
    i0 = np.nonzero(deg == 0)[0]
    idx = [np.nonzero((deg == 1) & (B[:, j] == 1))[0] for j in range(n)]
    if i0.size == 0 or any(k.size == 0 for k in idx) or not M[i0[0], i0[0]] > 0:
        return np.nan
    v = np.array([M[i0[0], k[0]] for k in idx]) / M[i0[0], i0[0]]
    return float(f.evaluate(v)) if np.all(np.isfinite(v)) else np.nan


def proven_empty(data, lb: LowerBound, problem=None, deadline=None) -> PsatzBound:
    """The claim "the constraint set is empty" of an UNBOUNDED solve, kept only when the ray is proven (module
    docstring); ``problem`` the image-form conic problem the ray belongs to (None: the claim is not checked and
    is withdrawn)."""
    from ..analysis.proof import global_psatz_bound
    from ..lowering.conic import GramForm

    if lb.status != SolveStatus.UNBOUNDED:
        return _wrap(lb)
    why = "no ray to check"
    st = data.structure
    sol = lb.solution
    d = None if sol is None else sol.x
    if problem is not None and problem.form == GramForm.IMAGE and d is not None and np.all(np.isfinite(d)) \
            and not st.free:
        d = np.asarray(d, float) / max(float(np.max(np.abs(d))), 1e-300)
        off = st.slots.offsets
        theta0 = np.array(data.theta, float)
        theta0[off[0]:off[1]] = 0.0                  # f = 0: the ray's own certificate
        zero = SimpleNamespace(structure=st, theta=theta0, ineq=data.ineq)
        grams = _ray_grams(problem, d)
        c_d = float(d[st.program.block("c").slice][0])
        ray = ProgramSolution(SolveStatus.OPTIMAL, c_d, d[: st.program.n_vars].copy(), grams)
        if c_d > 0:
            gb = global_psatz_bound(zero, ray, c_d, scale=0.0, deadline=deadline)
            if not gb.q_min > 0:
                return PsatzBound(SolveStatus.UNPROVEN, None, sol, lb.bracket,
                                  "every level is feasible, but the multiplier q is not proven positive: q may vanish "
                                  "on the set, so nothing is proven")
            proven = gb.lower_bound
            if not proven > 0:          # the multipliers of a ray are inexact too: its box bound, where there is one
                proven = max(proven, _ray_box_bound(zero, ray, c_d))
            if np.isfinite(proven) and proven > 0:
                return PsatzBound(SolveStatus.UNBOUNDED, np.inf, sol, lb.bracket,
                                  "c is unbounded: the constraint set is empty (the solver's ray proven: "
                                  f"0 >= {proven:.3g} on the set)")
            why = gb.message or "the ray's certificate is not proven"
        else:
            why = f"the ray does not raise the level (c_d = {c_d:.3g})"
    elif problem is not None and problem.form != GramForm.IMAGE:
        why = "rays are proven in the image form only"
    return PsatzBound(SolveStatus.NUMERICAL_ERROR, None, sol, lb.bracket,
                      f"{_RAY_FAILED} (an empty set), not proven: {why}")


def _ray_grams(problem, d: np.ndarray) -> dict:
    """The Gram matrices of the ray alone: smat(-A d) on every PSD block (image form)."""
    from ..algebra.svec import smat

    out = {}
    for blk in problem.psd_blocks:
        rows = slice(blk.row_start, blk.row_start + blk.size * (blk.size + 1) // 2)
        out[blk.name] = smat(-(problem.A[rows] @ d))
    return out


def _wrap(lb: LowerBound) -> PsatzBound:
    if isinstance(lb, PsatzBound):
        return lb
    rel = lb.lower_bound if lb.lower_bound is not None and np.isfinite(lb.lower_bound) else None
    return PsatzBound(lb.status, lb.lower_bound, lb.solution, lb.bracket, lb.message, relaxation=rel)


def balanced_recheck(structure, theta, lb: LowerBound, solve, prove: bool) -> LowerBound:
    """The claim INFEASIBLE (or an unproven ray, NUMERICAL_ERROR from :func:`proven_empty`) of a fixed-q solve
    re-decided on the balanced program (module docstring).  ``solve(psatz) -> LowerBound`` solves a
    :class:`~sospoly.certificates.psatz.PsatzProblem` (proven, no further re-check)."""
    from ..certificates.psatz import build_psatz
    from ..scaling import balancing, power2_normalised

    ray = lb.status == SolveStatus.NUMERICAL_ERROR and lb.message.startswith(_RAY_FAILED)
    if structure.free or not (lb.status == SolveStatus.INFEASIBLE or ray):
        return lb
    f, eq, ineq = structure.slots.polynomials(np.asarray(theta, float))
    sc = balancing([f, *eq, *ineq], len(structure.gens))
    if sc.is_identity:
        return lb
    fn, fs = power2_normalised(sc.polynomial(f))
    eqn = [power2_normalised(sc.polynomial(g))[0] for g in eq]
    ineqn = [power2_normalised(sc.polynomial(h))[0] for h in ineq]
    qn = power2_normalised(sc.polynomial(structure.q))[0]
    try:
        ps = build_psatz(fn, eqn, ineqn, structure.degree, qn, structure.gens, sparsity=structure.shape)
    except ValueError as exc:
        return _unconfirmed(lb, f"the balanced program could not be built ({exc})")
    other = solve(ps)
    what = "INFEASIBLE" if lb.status == SolveStatus.INFEASIBLE else "an unbounded level (an empty set)"
    if other.status == lb.status == SolveStatus.INFEASIBLE:
        return _wrap(LowerBound(lb.status, None, lb.solution, lb.bracket,
                                lb.message + " (the exactly balanced program says so too)"))
    if other.status == SolveStatus.UNBOUNDED:          # proven by proven_empty for the balanced program
        return PsatzBound(SolveStatus.UNBOUNDED, np.inf, None, lb.bracket, other.message + " (the exactly balanced "
                          f"program, v = 2^k w with k = {tuple(int(t) for t in sc.k)})")
    if other.lower_bound is not None and np.isfinite(other.lower_bound) and \
            other.status in (SolveStatus.OPTIMAL, SolveStatus.INACCURATE):
        c = float(other.lower_bound) * fs
        if not prove:
            return _unconfirmed(lb, f"the exactly balanced program has a certificate (c* = {c:.10g})")
        rel = getattr(other, "relaxation", None)
        return PsatzBound(SolveStatus.INACCURATE, c, None, lb.bracket,
                          f"the solver reported {what}, contradicted by the exactly balanced program (v = 2^k w, k = "
                          f"{tuple(int(t) for t in sc.k)}): its proven bound, times f's divisor {fs:g}; its "
                          "certificate is the balanced program's", relaxation=None if rel is None else rel * fs)
    return _unconfirmed(lb, f"the exactly balanced program gives {other.status.value}")


_RAY_FAILED = "the solver reported an unbounded level"


def _unconfirmed(lb: LowerBound, why: str) -> PsatzBound:
    return PsatzBound(SolveStatus.NUMERICAL_ERROR, None, lb.solution, lb.bracket,
                      f"{lb.message}; not confirmed: {why}")
