"""sospoly: sum-of-squares polynomial programming.

The layers, from meaning to numbers (docs/architecture.md draws them):

* :mod:`sospoly.algebra` -- sparse polynomials, monomial bases, Gram product tables, the svec convention;
* :mod:`sospoly.certificates` -- *what* is sought, as pure data: SOS programs, the Positivstellensatz
  program with its data slots, certificate shapes (dense, correlative/term sparsity, Newton polytope);
* :mod:`sospoly.lowering` -- *how* it becomes numbers: the conic standard form, compile-once structures;
* :mod:`sospoly.solvers` -- back-ends (Clarabel, cvxpy, the batched interior-point method), the
  a-posteriori checks, GEVP bisection, lower bounds of Positivstellensatz programs;
* :mod:`sospoly.analysis` -- minimisers (dense and clique-wise), certification by verification,
  rigorous bounds, complexity counts;
* :mod:`sospoly.tolerances` / :mod:`sospoly.budget` -- every tolerance and decision, every resource limit;
* :mod:`sospoly.minimize` -- ``minimize``; :mod:`sospoly.sos_check` -- ``is_sos``.
"""
from .algebra.basis import GramBasis, GramBlocks, MonomialIndex, monomials, sigma, tau
from .algebra.linpoly import LinPoly
from .algebra.polynomial import Polynomial, as_polynomial, det, sum_in_order, variables
from .analysis.complexity import n_lmivar_formula, n_lmivar_shape
from .analysis.extraction import Candidate, extract_from_gram, extract_from_moment
from .analysis.moments import MomentMatrix
from .analysis.rigor import ExactCheck, RigorousBound, exact_check, rigorous_psatz_bound
from .budget import DEFAULT_BUDGET, DEFAULT_TIME_LIMIT, UNLIMITED, Budget, BudgetExceeded, ProgramSize, estimate_size
from .certificates.program import Sense, SOSProgram
from .certificates.matrix_sos import MatrixSOSConstraint
from .certificates.dd import DDConstraint, DDKind
from .algebra.quadexpr import QuadExpr
from .certificates.psatz import (DataSlots, Multiplier, PsatzProblem, PsatzStructure, StructureMismatch, build_psatz,
                                 default_q, delta_min)
from .certificates.shape import CertificateShape, Sparsity, clique_shape, correlative_shape, dense_shape
from .certificates.reduction import diagonal_reduction, ideal_reduction, reduce_shape
from .lowering.conic import ConicProblem, GramForm, lower
from .ratios import RatioResult, minimize_ratios
from .minimize import MinimizeResult, SolveAttempt, candidates_of, feasibility_violation, minimize
from .sos_check import SOSResult, is_sos
from .solvers.compiled_solve import CompiledPsatz, PsatzCache, compile_psatz
from .solvers.gevp import CompiledGevp, GevpResult, bisect
from .solvers.lower_bound import solve_psatz
from .solvers.solve import (ConicResult, LowerBound, ProgramSolution, check_certificate, solve_conic_problem,
                            solve_program)
from .status import SolveStatus
from .scaling import pow2_above, pow2_above_array
from .tolerances import DEFAULT_TOLERANCES, Tolerances

__version__ = "0.2.0"

__all__ = [
    "GramBasis", "GramBlocks", "MonomialIndex", "monomials", "sigma", "tau", "LinPoly", "Polynomial", "sum_in_order",
    "as_polynomial", "det", "variables", "n_lmivar_formula", "n_lmivar_shape", "Candidate", "extract_from_gram",
    "extract_from_moment", "ExactCheck", "RigorousBound", "exact_check", "rigorous_psatz_bound", "DEFAULT_BUDGET",
    "UNLIMITED", "Budget", "BudgetExceeded", "ProgramSize", "estimate_size", "Sense", "SOSProgram", "DataSlots",
    "Multiplier", "PsatzProblem", "PsatzStructure", "StructureMismatch", "build_psatz", "default_q", "delta_min",
    "CertificateShape", "clique_shape", "correlative_shape", "dense_shape", "diagonal_reduction", "ideal_reduction",
    "reduce_shape", "CompiledPsatz", "PsatzCache",
    "compile_psatz", "ConicProblem", "GramForm", "lower", "MinimizeResult", "SolveAttempt", "SOSResult",
    "candidates_of", "feasibility_violation", "is_sos", "minimize", "CompiledGevp", "GevpResult", "bisect",
    "solve_psatz", "LowerBound", "ProgramSolution", "check_certificate", "solve_program", "SolveStatus",
    "DEFAULT_TOLERANCES", "Tolerances",
    "MomentMatrix", "MatrixSOSConstraint", "DDConstraint", "DDKind", "QuadExpr", "ConicResult",
    "RatioResult", "minimize_ratios", "solve_conic_problem", "DEFAULT_TIME_LIMIT", "Sparsity", "pow2_above",
    "pow2_above_array",
]
