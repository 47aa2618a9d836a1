"""Every numerical tolerance of sospoly, in one place.

All tolerances are gathered in the frozen dataclass :class:`Tolerances`; pass a
modified copy (``dataclasses.replace(DEFAULT_TOLERANCES, ...)``) to any entry point
that takes ``tolerances=``.

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
  degree 10) have eigenvalues around -1e-5 and are rejected.
* ``gevp_psd_margin``: the stricter margin for accepting a bisection level of the
  GEVP (see :mod:`sospoly.solvers.gevp`): above the optimum c*, lambda_min(G_u) is about
  -(c - c*)/2, so the general margin would let accepted levels creep ~1e-7 above c*.
* ``identity_residual``: maximal coefficient mismatch (relative to the largest
  coefficient of the polynomial) between u(v) and b(v)^T G b(v) for a certificate
  to be accepted (the image form is exact by construction; the kernel form and
  the cvxpy back-end are checked with this).
* ``gap_abs`` / ``gap_rel``: ``optimal`` is reported only when
  ``upper - lower <= gap_abs + gap_rel * max(1, |upper|)``, both sides computed
  from the solver's returned certificate and an exactly evaluated feasible point.
  With solver tolerances 1e-9 the bound itself is accurate to ~1e-8 relative;
  extracted minimisers carry ~1e-5..1e-7 error whose effect on f is quadratic
  near a minimiser, so 1e-6 / 1e-6 separates "equal" from "not equal" with two
  decades of margin either way.
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
* ``bisection_abs`` / ``bisection_rel``: the GEVP bisection stops when the bracket
  ``[c_lo, c_hi]`` satisfies ``c_hi - c_lo <= bisection_abs + bisection_rel*max(1,|c_lo|)``.
"""
from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Tolerances", "DEFAULT_TOLERANCES"]


@dataclass(frozen=True)
class Tolerances:
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

    def certified(self, lower: float | None, upper: float | None) -> bool:
        """Is ``upper - lower`` within the documented optimality tolerance?"""
        if lower is None or upper is None:
            return False
        return upper - lower <= self.gap_abs + self.gap_rel * max(1.0, abs(upper))


DEFAULT_TOLERANCES = Tolerances()
