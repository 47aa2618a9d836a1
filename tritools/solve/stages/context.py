"""The per-point context every stage reads and writes, and the per-step state of the SDP stages.

:class:`PointContext` holds one triangulation's data (the caller's cameras and the re-centred ones of
:mod:`tritools.model.frame`, the regions), its options and :class:`~tritools.solve.settings.SolveSettings`,
the normalisation (computed on first use: a point certified by the vectorised verification never needs
it), the problems built so far, the local estimate, the degree plan, the attempts and the timings, and
the best result so far.  :class:`StepState` is what the stages of one plan step pass along (problem,
Positivstellensatz program, lower bound, estimate, result).
"""
from __future__ import annotations

import dataclasses
import enum
import functools
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ...model.cameras import camera_refusal
from ...model.constraints import Method, centre_relations
from ...model.frame import WorldFrame, frame_centre_groups
from ...model.geometry import gamma as gamma_of
from ...model.micro_baseline import admitted_pairs
from ...model.normalize import Normalization, normalization_for
from ...model.problem import TriangulationProblem, build_problem
from ...result import Attempt, TriangulationResult
from ..fastpath_cameras import framed_cameras
from ..options import TriangulationOptions
from ..plan import Step
from ..settings import SolveSettings, call_deadline
from ..trivial import local_estimate

__all__ = ["AttemptStep", "ImplName", "Implementation", "PointContext", "StepState", "FAST_DEFAULT", "fast_names"]


class AttemptStep(str, enum.Enum):
    """``Attempt.step``: which stage produced an attempt (the values are the strings of the JSON form)."""
    VERIFICATION = "verification"       #: certification by verification (vectorised or generic)
    SDP = "sdp"                         #: one SDP of the degree plan
    TIGHT = "tight"                     #: the same SDP re-solved with 100x tighter solver tolerances
    SDP_BATCH = "sdp-batch"             #: the batched delta = 2 SDP (:mod:`tritools.solve.sdp_batch`)
    TRIVIAL_BOUND = "trivial_bound"     #: the trivial lower bound 0 (:mod:`tritools.solve.trivial`)
    SUB_PROBLEM = "sub-problem"         #: the problem without views holding the estimate (:mod:`.subproblem`)
    RETRY = "retry"                     #: a retry step of a batch
    CALL = "call"                       #: a call that raised (a batch's failed item)

    def __str__(self) -> str:
        return self.value

    def __hash__(self) -> int:          # equal to its string, so hashed like it (an Attempt read back from JSON)
        return str.__hash__(self)


class ImplName(str, enum.Enum):
    """The names of the stage implementations (:class:`Implementation`); ``fast`` sets hold the fast ones."""
    VERIFY_POINTS = "verify-points"     #: vectorised verification of point regions (:mod:`tritools.solve.fastpath`)
    VERIFY_DISCS = "verify-discs"       #: vectorised verification of discs (:mod:`tritools.solve.discs`)
    VERIFY_ELLIPSES = "verify-ellipses"  #: vectorised verification of filled ellipses (:mod:`tritools.solve.ellipses`)
    VERIFY_REGIONS = "verify-regions"   #: verification of every region type (:mod:`tritools.solve.regions_verify`)
    SDP_POINTS = "sdp-points"           #: the batched delta = 2 SDP of point regions (:mod:`tritools.solve.sdp_batch`)
    GENERIC = "generic"                 #: the generic implementation of a stage

    def __str__(self) -> str:
        return self.value

    def __hash__(self) -> int:
        return str.__hash__(self)


#: the fast implementations a single call uses by default (names of :mod:`tritools.solve.stages.verify` and
#: :mod:`tritools.solve.stages.sdp`): the vectorised verification on a stack of one; the batched SDP is for
#: stacks, and a single call keeps the generic SDP (the reference the batch is tested against).
FAST_DEFAULT = frozenset({ImplName.VERIFY_POINTS, ImplName.VERIFY_DISCS, ImplName.VERIFY_ELLIPSES,
                          ImplName.VERIFY_REGIONS})


def fast_names(fast) -> frozenset:
    """``fast`` (names or :class:`ImplName` members) as a set of members; ValueError naming ``fast`` otherwise."""
    if fast is FAST_DEFAULT:            # (every single call: members already)
        return fast
    out = set()
    for name in fast:
        try:
            out.add(ImplName(name))
        except ValueError:
            known = ", ".join(repr(n.value) for n in ImplName if n != ImplName.GENERIC)
            raise ValueError(f"fast: unknown implementation {name!r}; known: {known}") from None
    return frozenset(out)


@dataclass(frozen=True)
class Implementation:
    """One implementation of a stage: ``applies(ctx, item)`` says whether it can run on the item (a plan
    step for ``verify``, the step state for ``sdp``), ``run(ctx, item)`` gives the stage's answer.  ``fast``
    implementations also need their name in ``ctx.fast``."""
    name: ImplName
    applies: Callable
    run: Callable
    fast: bool = True

    def usable(self, ctx: PointContext, item) -> bool:
        return (not self.fast or self.name in ctx.fast) and self.applies(ctx, item)


def sparsity_name(step: Step) -> str:
    return "dense" if step.formulation == "dense" else "views"


def bound_stop_reached(stop, gamma_lb, certified: bool) -> bool:
    """The rule of ``lower_bound_stop`` (the best-bound stop of the degree plan): an uncertified result whose
    rigorous gamma_lb is at the level ``stop`` (None: never) ends the plan; single calls
    (:meth:`PointContext.bound_reached`) and the batch's degree-2 SDP rows alike."""
    return stop is not None and not certified and gamma_lb is not None and gamma_lb >= stop


class PointContext:
    """One triangulation in progress (module docstring).  ``stages`` / ``step_stages``: the pipelines run
    (:mod:`tritools.solve.stages`); ``fast``: the names of the fast implementations allowed."""

    def __init__(self, cams, regions, opts: TriangulationOptions, t0: float, *, stages=(), step_stages=(),
                 fast=FAST_DEFAULT):
        self.frame: WorldFrame                              # georeferenced worlds, rescaled cameras
        self.frame, self.cams = framed_cameras(cams)        # (remembered for the last cameras)
        self.cams_user = cams                               # the caller's: the final report is made on these
        self.regions, self.opts, self.t0 = regions, opts, t0
        self.N = self.cams.shape[0]
        self.settings = SolveSettings.from_options(opts, call_deadline(opts, t0, regions))   # the limit counts from t0
        self.stages, self.step_stages, self.fast = tuple(stages), tuple(step_stages), fast_names(fast)
        self.timings: dict = {}
        self.attempts: list[Attempt] = []
        self.steps: list[Step] = []
        self.best: TriangulationResult | None = None
        self.skipped: TriangulationResult | None = None     # a step that exceeded the budget
        self.verify_cut = False                             # the verification's bound did not fit in the time left
        self.finished = False                               # a stage decided the point: the walk stops
        self.estimate_n: tuple | None = None                # the steps' best (gamma_n, X_n, X_raw_n, x*_n)
        self._problems: dict = {}
        self._relations = None
        self._local = _UNSET

    @property
    def tolerances(self):
        return self.settings.tolerances

    @property
    def bound_reached(self) -> bool:
        """Whether the best result so far is uncertified with a rigorous gamma_lb at the options'
        ``lower_bound_stop`` (no more steps then: :mod:`tritools.solve.stages.sdp`)."""
        best = self.best
        return best is not None and bound_stop_reached(self.opts.lower_bound_stop, best.gamma_lb,
                                                       best.status.certified)

    @property
    def expired(self) -> bool:
        return self.settings.deadline.expired

    def tick(self, name: str, t: float) -> None:
        """Add the seconds since ``t`` to ``timings[name]``."""
        self.timings[name] = self.timings.get(name, 0.0) + time.perf_counter() - t

    # ------------------------------------------------------------------ the normalised data (when needed)
    @functools.cached_property
    def norm(self) -> Normalization:
        """The normalisation (:mod:`tritools.model.normalize`), computed on first use."""
        t = time.perf_counter()
        norm = normalization_for(self.cams, self.regions, enabled=self.opts.normalize)
        self.tick("normalise", t)
        return norm

    @functools.cached_property
    def cams_n(self) -> np.ndarray:
        return self.norm.cameras(self.cams)

    @functools.cached_property
    def cams_n_refusal(self) -> str | None:
        """Why the normalised cameras fail the camera rule (:func:`~tritools.model.cameras.validate_cameras`'s
        message), None when they pass.  The caller's cameras passed it: a refusal here means image data so far from
        the cameras' image scale (regions at ~1e308 px) that the normalisation cannot represent them (review 29b F8)."""
        return camera_refusal(self.cams_n)

    @functools.cached_property
    def regs_n(self) -> list:
        return self.norm.regions(self.regions)

    def centres(self) -> np.ndarray:
        return np.array([r.center for r in self.regions], float)

    def problem(self, method, formulation: str) -> TriangulationProblem:
        """(f, g, h) of the normalised data in ``formulation`` (built once per (method, formulation))."""
        key = (method, formulation)
        if key not in self._problems:
            t = time.perf_counter()
            twin = next((p for (m, _), p in self._problems.items() if m == method == Method.COROLLARY1), None)
            if twin is not None:            # Corollary 1's polynomials do not depend on the formulation
                self._problems[key] = dataclasses.replace(twin, formulation=formulation)
            else:
                if self._relations is None:
                    self._relations = self._centre_relations()
                self._problems[key] = build_problem(self.cams_n, self.regs_n, method, formulation, self._relations)
            self.tick("build", t)
        return self._problems[key]

    def _centre_relations(self):
        """Which views share a centre (:func:`~tritools.model.constraints.centre_relations`): exactly on the caller's
        cameras, or to round-off where the micro-baseline's ball is excluded by the local estimate's cost
        (:mod:`tritools.model.micro_baseline`)."""
        groups = frame_centre_groups(self.cams, self.frame)
        raw = np.asarray(self.cams_user, float)
        rel = centre_relations(self.cams, groups, raw=raw)
        if not rel.untied:
            return rel
        local = self.local()
        f_upper = None
        if local is not None:
            g = float(gamma_of(self.norm.world_point(local[1]), self.cams, self.regions))
            f_upper = 2 * self.N * g * g
        floor = 8 * np.finfo(float).eps * float(np.linalg.norm(self.frame.origin))
        admitted = admitted_pairs(raw, self.cams, self.regions, groups, f_upper, floor, rel.untied)
        return centre_relations(self.cams, groups, raw=raw, admitted=admitted) if admitted else rel

    def local(self) -> tuple[float, np.ndarray] | None:
        """The local estimate (:func:`tritools.solve.trivial.local_estimate`), computed once."""
        if self._local is _UNSET:
            t = time.perf_counter()
            try:
                self._local = local_estimate(self.cams_n, self.regs_n)
            except (ValueError, np.linalg.LinAlgError, FloatingPointError):
                self._local = None
            self.timings["local"] = time.perf_counter() - t
        return self._local


@dataclass
class StepState:
    """One plan step in progress: the stages of :data:`tritools.solve.stages.STEP_STAGES` fill it in turn and
    set ``result`` when the step is decided (the remaining step stages are then skipped)."""
    step: Step
    tight: bool = False
    t0: float = field(default_factory=time.perf_counter)
    tol: object = None                  # the solver tolerances of this step (tightened for a re-solve)
    problem: TriangulationProblem | None = None
    psatz: object = None                # the Positivstellensatz program (bound compiled instance or built)
    lb: object = None                   # sospoly's LowerBound
    t_solve: float = 0.0                # when the solve started (for the timings)
    c_lower: float | None = None        # c_LB in normalised units (made rigorous by the rigor stage)
    estimate: tuple | None = None       # (gamma_n, X_n, X_raw_n, image points_n) of the best candidate
    shortcut: bool | None = None        # the estimate is an earlier step's (True), spent (False), not tried (None)
    result: TriangulationResult | None = None
    final: bool = False                 # the step is decided: the remaining step stages are skipped
    recorded: bool = False              # its attempt is recorded already (a step that failed early)

    @property
    def label(self) -> AttemptStep:
        return AttemptStep.TIGHT if self.tight else AttemptStep.SDP

    @property
    def sparsity(self) -> str:
        return sparsity_name(self.step)


#: "not computed yet" (the local estimate may be None)
_UNSET = object()
