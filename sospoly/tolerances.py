"""Every numerical tolerance of sospoly, and every decision made with one, in one place.

:class:`Tolerances` holds the numbers; its methods are the only place where a tolerance
becomes a decision (is this a certificate? do these bounds contradict each other? is this
Gram matrix PSD? how large is this kernel?).  Every path -- a single SOS solve, the batched
interior-point method, the verification fast path, the triangulation front-end -- calls
these methods, and every method accepts scalars or numpy arrays (elementwise), so a
vectorised path decides exactly as the scalar one.  Pass a modified copy
(``dataclasses.replace(DEFAULT_TOLERANCES, ...)``) to any entry point that takes
``tolerances=``; the constructor refuses non-finite, negative or mistyped values.

The certificate rule
--------------------
A lower bound ``lower`` (from a checked certificate) and an upper bound ``upper`` (the
objective at an exactly evaluated feasible point) *meet* when

    upper - lower <= gap_tolerance(upper, scale),
    gap_tolerance(upper, scale) = gap_abs * scale + gap_rel * max(scale, |upper|),

where ``scale`` is the problem's own scale (the largest coefficient of the objective for
:func:`sospoly.minimize`; 1 for the triangulation's normalised units, where c = O(1) is
arranged by the normalisation).  They *contradict* each other when
``lower - upper > gap_tolerance(upper, scale)``: a numerical failure, never a certificate.
When they meet with ``lower > upper`` (inside the tolerance), :meth:`Tolerances.consistent`
reports ``lower = upper``, so a result never claims ``lower > upper``.

Why these values
----------------
* ``solver_*``: Clarabel's interior-point stopping tolerances.  We run one decade
  tighter than Clarabel's defaults (1e-8) so that the reported bound carries
  about 8-9 significant digits on well-scaled problems.
* ``psd_margin``: a Gram matrix G returned by the solver is accepted as positive
  semidefinite when ``lambda_min(G) >= -psd_margin * max(1, max|G_ij|)``.  Interior
  point methods return points strictly inside the cone up to their feasibility
  tolerance, so a genuine certificate passes with room to spare, while the
  "optimal but infeasible" answers seen on near-degenerate problems (Motzkin at
  degree 10) have eigenvalues around -1e-5 and are rejected.  The small negative part
  that *is* accepted is not ignored: :mod:`sospoly.analysis.rigor` subtracts its effect
  from the bound (rigorous lower bounds).
* ``gevp_psd_margin``: the stricter margin for accepting a bisection level of the
  GEVP (see :mod:`sospoly.solvers.gevp`): above the optimum c*, lambda_min(G_u) is about
  -(c - c*)/2, so the general margin would let accepted levels creep ~1e-7 above c*.
* ``identity_residual``: maximal coefficient mismatch (relative to the largest
  coefficient of the polynomial) between u(v) and b(v)^T G b(v) for a certificate
  to be accepted (the image form is exact by construction; the kernel form and
  the cvxpy back-end are checked with this).
* ``gap_abs`` / ``gap_rel``: the certificate rule above.  With solver tolerances 1e-9 the
  bound itself is accurate to ~1e-8 relative; extracted minimisers carry ~1e-5..1e-7
  error whose effect on f is quadratic near a minimiser, so 1e-6 / 1e-6 separates
  "equal" from "not equal" with two decades of margin either way.
* ``feasibility``: a candidate point counts as feasible when every equality
  satisfies ``|g_k(v)| <= feasibility * max(1, ||coef(g_k)||_inf)`` and every
  inequality ``h_k(v) >= -feasibility * max(1, ||coef(h_k)||_inf)``.
* ``kernel_rel``: eigenvalues of a Gram matrix below ``kernel_rel * lambda_max``
  are treated as zero when extracting minimisers (and moment-matrix eigenvalues
  above ``moment_rank_rel * lambda_max`` count toward the rank).
* ``ipm_max_iter`` / ``ipm_step_fraction`` / ``ipm_divergence``: the batched
  interior-point solver (:mod:`sospoly.solvers.ipm`) stops after ``ipm_max_iter`` iterations
  (Mehrotra's method needs 10-25 on the well-scaled programs of the hot path, so 60
  only ends runs that will not converge), moves ``ipm_step_fraction`` of the way to
  the cone boundary, and declares divergence (a likely infeasible or unbounded
  program, handed to Clarabel) when |x| or |z| exceeds ``ipm_divergence``.  It stops
  on the same ``solver_*`` tolerances as Clarabel, or -- when large multipliers make the
  dual residual's contribution r_D^T x to the duality gap stall above them -- when the
  rest of the gap (complementarity) meets them and |r_D^T x| <= ``ipm_dual_residual_gap``
  * max(1, |objective|): the bound then agrees with Clarabel's to ~1e-7 relative, the
  accuracy at which the PSD margin of the a-posteriori check separates certificates.
* ``ipm_flat_face_dual_residual_gap``: the ``ipm_dual_residual_gap`` used for programs
  whose optimal multipliers form a long flat face (the batched Corollary 1 delta = 2
  path, :mod:`tritools.solve.sdp_batch`): with N >= 4 views the epipolar constraints are
  linearly dependent at v*, |r| ~ 1e3-1e5 at the face's analytic centre, and r_D^T x
  stalls at ~1e-7 relative while the complementarity part of the gap is ~1e-12.  On the
  Oxford instances that stalled under 1e-8 the accepted c* agrees with Clarabel's to
  <= 1.4e-9 (normalised c units); the Gram check and the certificate test still apply.
* ``ipm_schur_regularization``: the reduced (moment-form) path of
  :func:`sospoly.solvers.ipm.ipm_solve_sparse` factorises its Schur complement M + r I with
  r = ipm_schur_regularization * max diag(M) (raised 100x, at most twice, while M is
  numerically indefinite), and refines the solution with M itself.  Near the optimum M's
  entries span ~1e11 (the moment matrix tends to rank one); 1e-14 there biased the Newton
  directions enough to stall 2 of 10 Example 5 cases at a duality gap of 3e-8, machine
  precision (1e-16) converges on all of them.
* ``accept_inaccurate`` (a policy, default False): when True, a solver answer that stopped
  short of the ``solver_*`` tolerances (Clarabel's *almost solved*: its reduced tolerances,
  ~5e-5) but passes the a-posteriori checks ends the retry chain and is returned with status
  ``INACCURATE``, its objective and its Gram matrices -- never as ``OPTIMAL``.  Only for callers
  that turn the iterate into a rigorous bound themselves (:mod:`sospoly.analysis.rigor`, which
  charges the PSD defect and the identity residual to the bound over a box holding the
  minimiser): tritools does, so its bounds stay valid while large many-view programs are not
  re-solved three more times for the last digits.
* ``retry_budget_iterations`` / ``retry_budget_share`` / ``retry_budget_seconds``: when Clarabel's first full
  attempt on a program fails numerically, the retries with other settings
  (:data:`sospoly.solvers.backends.CLARABEL_RETRY_CHAIN`) share ``max(retry_budget_iterations, retry_budget_share
  * k_first, retry_budget_seconds / t_ref)`` interior-point iterations, k_first that attempt's iterations and t_ref
  the program's *reference* iteration time (:meth:`sospoly.budget.ClarabelTimeModel.reference_iteration`, a function
  of its size: cheap programs get more iterations).  Counted in iterations, not measured seconds, so that whether a
  retry rescues a program does not depend on the machine's load (a budget of 1 measured second certified a 9-view
  Theorem 1 program on a quiet machine and not with two other jobs beside it).  Clarabel takes 15-30 iterations
  on the SOS programs here; the default 60 is two such solves.  On a four-view rectified rig whose L2 optimum lies
  behind the cameras (review 27b F3), Theorem 1 at delta = 4 failed after 73 iterations (11 s) and the unbounded
  retries ran another 47 s to their iteration and time limits without an answer.  A retry stopped by the budget
  is a numerical failure (never ``time_limit``, which is the caller's limit); 0 / 0 / 0 makes no retry after a
  failed first attempt, a large value restores the unbounded chain.
* ``bisection_abs`` / ``bisection_rel``: the GEVP bisection stops when the bracket
  ``[c_lo, c_hi]`` satisfies ``c_hi - c_lo <= bisection_abs + bisection_rel*max(1,|c_lo|)``.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields

import numpy as np

__all__ = ["Tolerances", "DEFAULT_TOLERANCES", "as_tolerances"]

_INT_FIELDS = ("solver_max_iter", "bisection_max_steps", "ipm_max_iter")
_BOOL_FIELDS = ("accept_inaccurate",)


def _maybe_scalar(x):
    """A 0-d result as a Python scalar (bool or float), arrays unchanged."""
    return x.item() if isinstance(x, np.ndarray) and x.ndim == 0 else x


@dataclass(frozen=True)
class Tolerances:
    """The tolerances of sospoly (see the module docstring for every value) and the decisions made with them."""

    solver_gap_abs: float = 1e-9
    solver_gap_rel: float = 1e-9
    solver_feas: float = 1e-9
    solver_max_iter: int = 300
    psd_margin: float = 1e-7
    gevp_psd_margin: float = 1e-9
    identity_residual: float = 1e-7
    gap_abs: float = 1e-6
    gap_rel: float = 1e-6
    feasibility: float = 1e-6
    kernel_rel: float = 1e-6
    moment_rank_rel: float = 1e-4
    bisection_abs: float = 1e-7
    bisection_rel: float = 1e-7
    bisection_max_steps: int = 60
    ipm_max_iter: int = 60
    ipm_step_fraction: float = 0.95
    ipm_divergence: float = 1e10
    ipm_dual_residual_gap: float = 1e-8
    ipm_flat_face_dual_residual_gap: float = 1e-6
    ipm_schur_regularization: float = 1e-16
    retry_budget_share: float = 1.0
    retry_budget_seconds: float = 1.0
    accept_inaccurate: bool = False
    retry_budget_iterations: int = 60       # added last: the fields before it keep their positions (wave 33's order)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name in _BOOL_FIELDS:
                if not isinstance(v, bool):
                    raise ValueError(f"Tolerances.{f.name} must be True or False, got {v!r}")
                continue
            if f.name == "retry_budget_iterations":
                if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 0:
                    raise ValueError(f"Tolerances.{f.name} must be an integer >= 0, got {v!r}")
                continue
            if f.name in _INT_FIELDS:
                if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 1:
                    raise ValueError(f"Tolerances.{f.name} must be a positive integer, got {v!r}")
                continue
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or v < 0:
                raise ValueError(f"Tolerances.{f.name} must be a finite number >= 0, got {v!r}")
        if not 0 < self.ipm_step_fraction < 1:
            raise ValueError(f"Tolerances.ipm_step_fraction must lie in (0, 1), got {self.ipm_step_fraction!r}")

    # ------------------------------------------------------------------ the certificate rule
    def gap_tolerance(self, upper, scale=1.0):
        """``gap_abs * scale + gap_rel * max(scale, |upper|)``: the largest gap that still certifies."""
        upper = np.asarray(upper, float)
        scale = np.asarray(scale, float)
        return _maybe_scalar(self.gap_abs * scale + self.gap_rel * np.maximum(scale, np.abs(upper)))

    def gap_tolerance_one(self, upper: float, scale: float = 1.0) -> float:
        """The scalar twin of :meth:`gap_tolerance` for one finite float ``upper`` (plain Python arithmetic, the
        same operations: a single call's decision without numpy)."""
        return self.gap_abs * scale + self.gap_rel * max(scale, abs(upper))

    def certified_relatively_one(self, lower: float, upper: float, share: float = 1.0) -> bool:
        """The scalar twin of :meth:`certified_relatively` for floats; within ``share`` of the relative gap
        (``upper - lower <= share gap_rel |upper|``: a caller that prunes with a margin to spare)."""
        return upper - lower <= share * self.gap_rel * abs(upper)

    def certified_one(self, lower, upper, scale: float = 1.0) -> bool:
        """The scalar twin of :meth:`certified` for one pair of floats (plain Python arithmetic, the same rule: a
        single call's decision without numpy)."""
        if lower is None or upper is None:
            return False
        lo, up = float(lower), float(upper)
        return math.isfinite(up) and not math.isnan(lo) and up - lo <= self.gap_tolerance_one(up, float(scale))

    def contradicts_one(self, lower, upper, scale: float = 1.0) -> bool:
        """The scalar twin of :meth:`contradicts` for one pair of floats."""
        if lower is None or upper is None:
            return False
        lo, up = float(lower), float(upper)
        return math.isfinite(lo) and math.isfinite(up) and lo - up > self.gap_tolerance_one(up, float(scale))

    def solver_gap_within(self, primal: float, dual: float, share: float = 1.0) -> bool:
        """Is a solver's own duality gap within ``1 / share`` of the rule's relative part:
        ``|p - d| <= (gap_rel / share) max(1, min(|p|, |d|))``?  (An iterate accepted as "almost solved" by it is
        made rigorous by its caller: :func:`sospoly.solvers.backends.ipm_almost_solved`.)"""
        gap = abs(primal - dual) / max(1.0, min(abs(primal), abs(dual)))
        return gap <= self.gap_rel / share

    def certified(self, lower, upper, scale=1.0):
        """Do ``lower`` and ``upper`` meet (``upper - lower <= gap_tolerance``)?  False where either
        is None or NaN.  Scalars give a bool, arrays an elementwise boolean array."""
        if lower is None or upper is None:
            return False
        lo, up = np.asarray(lower, float), np.asarray(upper, float)
        with np.errstate(invalid="ignore"):
            out = np.isfinite(up) & ~np.isnan(lo) & (up - lo <= self.gap_tolerance(up, scale))
        return _maybe_scalar(out)

    def certified_relatively(self, lower, upper):
        """Does the gap pass through the relative part of the rule alone (``upper - lower <= gap_rel |upper|``)?
        Where it passes only through ``gap_abs`` (upper ~ 0), a caller may ask for more (tritools: the
        coordinates' resolution).  Scalars give a bool, arrays an elementwise boolean array."""
        lo, up = np.asarray(lower, float), np.asarray(upper, float)
        with np.errstate(invalid="ignore"):
            out = up - lo <= self.gap_rel * np.abs(up)
        return _maybe_scalar(out)

    def contradicts(self, lower, upper, scale=1.0):
        """Is ``lower`` above ``upper`` by more than the tolerance (a numerical failure)?"""
        if lower is None or upper is None:
            return False
        lo, up = np.asarray(lower, float), np.asarray(upper, float)
        with np.errstate(invalid="ignore"):
            out = np.isfinite(lo) & np.isfinite(up) & (lo - up > self.gap_tolerance(up, scale))
        return _maybe_scalar(out)

    def consistent(self, lower, upper):
        """The lower bound to report beside ``upper``: ``min(lower, upper)`` (a lower bound that exceeds a
        feasible value within the tolerance is reported as that value; beyond it the caller must already
        have declared a numerical failure with :meth:`contradicts`)."""
        if lower is None or upper is None:
            return lower
        lo, up = np.asarray(lower, float), np.asarray(upper, float)
        with np.errstate(invalid="ignore"):
            out = np.where(np.isfinite(up) & (lo > up), up, lo)
        return _maybe_scalar(out)

    # ------------------------------------------------------------------ matrices
    def psd_accepts(self, lambda_min, max_abs_entry, floor=1.0):
        """Is a Gram matrix with smallest eigenvalue ``lambda_min`` and largest entry ``max_abs_entry``
        accepted as PSD: ``lambda_min >= -psd_margin * max(floor, max_abs_entry)``?  ``floor``: 1, or the
        program's own scale where that is smaller (:func:`sospoly.solvers.solve.check_certificate`: a floor of 1
        is an absolute margin for a program whose coefficients are all far below 1)."""
        lam = np.asarray(lambda_min, float)
        return _maybe_scalar(lam >= -self.psd_margin * np.maximum(floor, np.asarray(max_abs_entry, float)))

    def kernel_dimension(self, eigenvalues):
        """Number (>= 1) of numerically zero eigenvalues, ``lambda <= kernel_rel * |lambda_max|``, of
        ascending eigenvalues along the last axis."""
        lam = np.asarray(eigenvalues, float)
        top = np.maximum(np.abs(lam[..., -1:]), 1e-300)
        return _maybe_scalar(np.maximum(1, np.sum(lam <= self.kernel_rel * top, axis=-1)))

    def range_mask(self, eigenvalues):
        """Which eigenvalues of a Gram matrix are numerically non-zero, ``lambda > kernel_rel * |lambda_max|`` (the
        complement of :meth:`kernel_dimension`'s kernel, possibly all of them): the range a face re-fit keeps
        (:func:`sospoly.is_sos`)."""
        lam = np.asarray(eigenvalues, float)
        top = np.maximum(np.abs(lam[..., -1:]), 1e-300)
        return lam > self.kernel_rel * top

    def identity_accepts(self, residual):
        """Is a coefficient identity with relative residual ``residual`` accepted (``<= identity_residual``)?"""
        return _maybe_scalar(np.asarray(residual, float) <= self.identity_residual)

    def moment_rank_mask(self, eigenvalues):
        """Which eigenvalues of a moment matrix count toward its rank (``>= moment_rank_rel * lambda_max``);
        at least the largest one."""
        lam = np.asarray(eigenvalues, float)
        keep = lam >= self.moment_rank_rel * max(float(lam.max()), 1e-300) if lam.size else lam.astype(bool)
        if lam.size and not keep.any():
            keep[np.argmax(lam)] = True
        return keep

    def feasible(self, violation):
        """Is a point with relative constraint violation ``violation`` feasible?"""
        return _maybe_scalar(np.asarray(violation, float) <= self.feasibility)

    def tightened(self, factor: float = 1e-2) -> Tolerances:
        """A copy with the solver's stopping tolerances multiplied by ``factor`` (a re-solve after an
        inconsistent answer)."""
        from dataclasses import replace

        return replace(self, solver_gap_abs=self.solver_gap_abs * factor, solver_gap_rel=self.solver_gap_rel * factor,
                       solver_feas=self.solver_feas * factor)


DEFAULT_TOLERANCES = Tolerances()


def as_tolerances(value) -> Tolerances:
    """``value`` if it is a :class:`Tolerances`, :data:`DEFAULT_TOLERANCES` for None; TypeError otherwise
    (the one input check of every ``tolerances=`` argument)."""
    if value is None:
        return DEFAULT_TOLERANCES
    if not isinstance(value, Tolerances):
        raise TypeError(f"tolerances must be a sospoly.Tolerances, got {type(value).__name__}")
    return value
