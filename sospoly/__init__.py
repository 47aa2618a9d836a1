"""sospoly: sum-of-squares polynomial programming.

The layers, from meaning to numbers:

* :mod:`sospoly.algebra.polynomial` -- sparse polynomials (``variables``, ``Polynomial``, ``det``);
* :mod:`sospoly.algebra.basis` -- monomial bases, ``sigma``, ``tau``, Gram product tables;
* :mod:`sospoly.certificates.program` -- SOS programs as pure data (decision polynomials, SOS constraints);
* :mod:`sospoly.certificates.psatz` -- Positivstellensatz certificates for lower bounds (SPEC §5);
* :mod:`sospoly.lowering.conic` -- lowering to one conic standard form (image or kernel Gram form);
* :mod:`sospoly.solvers.backends` / :mod:`sospoly.solvers.solve` -- Clarabel (direct) or cvxpy, with
  a-posteriori certificate checks;
* :mod:`sospoly.lowering.compiled` -- compile a Positivstellensatz structure once, fill numbers per
  instance, solve batches; :mod:`sospoly.solvers.ipm` -- the batched interior-point method;
* :mod:`sospoly.solvers.gevp` -- bisection for the free-multiplier GEVP;
* :mod:`sospoly.analysis.extraction` -- minimisers from Gram kernels and moment matrices;
* :mod:`sospoly.minimize` -- ``minimize`` and ``is_sos``.
"""
from .algebra.basis import GramBasis, MonomialIndex, monomials, sigma, tau
from .lowering.compiled import DEFAULT_CACHE, CompiledPsatz, PsatzCache, StructureMismatch, compile_psatz
from .analysis.complexity import n_lmivar_formula
from .lowering.conic import ConicProblem, GramForm, lower
from .analysis.extraction import Candidate, extract_from_gram, extract_from_moment
from .solvers.gevp import CompiledGevp, GevpResult, bisect
from .algebra.linpoly import LinPoly
from .minimize import (LowerBound, MinimizeResult, SOSResult, candidates_of, feasibility_violation, is_sos, minimize,
                       solve_psatz)
from .algebra.polynomial import Polynomial, as_polynomial, det, variables
from .certificates.program import Sense, SOSProgram
from .certificates.psatz import Multiplier, PsatzProblem, build_psatz, default_q, delta_min
from .solvers.solve import ProgramSolution, check_certificate, solve_program
from .status import SolveStatus
from .tolerances import DEFAULT_TOLERANCES, Tolerances

__version__ = "0.1.0"

__all__ = [
    "GramBasis", "MonomialIndex", "monomials", "sigma", "tau", "n_lmivar_formula", "ConicProblem", "GramForm",
    "lower", "Candidate", "extract_from_gram", "extract_from_moment", "CompiledGevp", "GevpResult", "bisect",
    "LinPoly", "LowerBound", "candidates_of", "solve_psatz", "MinimizeResult", "SOSResult", "feasibility_violation", "is_sos", "minimize", "Polynomial",
    "as_polynomial", "det", "variables", "Sense", "SOSProgram", "Multiplier", "PsatzProblem", "build_psatz",
    "default_q", "delta_min", "ProgramSolution", "check_certificate", "solve_program", "SolveStatus",
    "DEFAULT_TOLERANCES", "Tolerances", "CompiledPsatz", "PsatzCache", "StructureMismatch", "compile_psatz",
    "DEFAULT_CACHE",
]
