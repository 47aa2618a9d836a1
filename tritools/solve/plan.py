"""The degree plan of a triangulation: which (method, delta, formulation) steps to try, in order.

With ``method="auto"`` (the default everywhere):

1. Corollary 1 at delta = 2 -- the paper's economical certificate, a (2N + sum n_i + 1)-sided Gram
   matrix; with ``path="auto"`` certification by verification is tried before it;
2. Corollary 1 at delta = 4 (up to ``max_delta``, default 4): *dense* while the dense Gram matrix has
   side <= :data:`DENSE_MAX_SIDE` (at most 8 variables: e.g. 4 views with point regions), else the
   *views* formulation (view cliques, :mod:`tritools.model.problem`): clique-wise degree-4 blocks over
   a cyclic band of view pairs (:func:`~tritools.model.problem.view_band`; Theorem 1: a chain of view
   triples) beside the dense degree-2 certificate, so it is never weaker than step 1 and its cost grows
   linearly with N (benchmarks/manyview.py: N = 30 mixed regions in ~40 s); when the views step does not
   certify and the dense Gram side is at most :data:`DENSE_FALLBACK_SIDE` (e.g. 5 views with point
   regions, ~2 s) or the problem has three views, the dense certificate at the same degree follows (it
   contains the views one).  Two views, and Theorem 1 with three (one clique holds every view), stay dense.

After the plan, for the problems it leaves uncertified, the point stage ``exact_variety``
(:mod:`tritools.solve.stages.exact`) runs one more step, :func:`exact_variety_step`: Theorem 1 at delta = 4, dense
(with ``method="auto"``, a plan reaching delta = 4, at least 3 views and a dense Gram side of at most
:data:`EXACT_VARIETY_MAX_SIDE`: 3 or 4 views with point regions).  Corollary 1's constraints -- the epipolar
relations of the view pairs -- say that the back-projected rays meet pairwise; rays that meet pairwise meet in one
point *or lie in one plane*, and that plane holds every camera centre.  So when the centres are coplanar (always
with three views: the trifocal plane; with more, a planar camera path) the epipolar variety has a second
component: every view's image point on the image line of that plane, whatever the others.  When the observations
lie far from every projection (tens to hundreds of px: a wrong match kept as an inlier under a robust threshold of
200 px) and the scene point lies near that plane, moving each observation to its line alone costs less than the L2
optimum, and Corollary 1's bound stops at that cost at every degree (measured: the same bound at delta = 2, 4 and
6, equal to the sum of the squared distances to those lines, e.g. 44.9 px against the optimum 57.4 px).  Theorem
1's minors (SPEC §3; the three- and four-view minors among them) vanish exactly on the image points of scene
points, and its dense degree-4 certificate closes the gap (benchmarks/RESULTS.md, "Robust": the 3-view misses,
0.05-0.4 s each; 4 views with coplanar centres, 0.4-0.9 s).  Its view-clique formulation did not (5-6 views:
solver failures), and the dense one at 5 views costs ~7 s: neither is tried.

The same component also caps Corollary 1 with ordinary noise when the point lies in or near the centres' plane
(a turntable): its bound is at most s_pi = sum_i dist(x^_i, l_i)^2 at every degree, so the ``steps`` stage stops
the plan after a Corollary 1 step whose bound sits on s_pi below the upper bound
(:func:`tritools.solve.coplanar.futile_after`; the exact-variety step still follows where it applies, and with 5 to
:data:`EXACT_VARIETY_VIEWS_MAX` views its view-clique form, :func:`exact_variety_views_step`, cheap but certifying
only some of them).

With an explicit method, the degrees run from ``delta`` (default delta_min) to ``max_delta`` (default
``delta`` when given, else delta_min + 2) with that method; ``sparsity`` ("none" / "views") forces
the formulation of the steps above delta = 2.  Theorem 1's dense formulation holds all C(2N, 4)
minors and is used for at most :data:`~tritools.model.constraints.THEOREM1_DENSE_MAX_VIEWS` views.
"""
from __future__ import annotations

from dataclasses import dataclass

from sospoly import GramForm, Multiplier, sigma

from ..model.constraints import THEOREM1_DENSE_MAX_VIEWS, Method
from .options import MethodChoice, SolvePath, Sparsity, TriangulationOptions

__all__ = ["Step", "degree_plan", "delta_min", "batch_steps", "last_delta", "DENSE_MAX_SIDE", "DENSE_FALLBACK_SIDE",
           "EXACT_VARIETY_MAX_SIDE", "exact_variety_step", "exact_variety_applies",
           "exact_variety_views_step", "EXACT_VARIETY_VIEWS_MAX", "EXACT_VARIETY_COLLINEAR_MAX"]

#: ``sparsity="auto"``: dense certificates above degree 2 while the Gram side stays at most this (sigma(8, 2) = 45).
DENSE_MAX_SIDE = 45
#: ``sparsity="auto"``: a views step that does not certify is followed by the dense one up to this side
#: (sigma(11, 2) = 78: 5 views with point regions, N_LMIVAR ~2400, ~2 s on one core).
DENSE_FALLBACK_SIDE = 78
#: ``method="auto"``: the exact-variety step (:func:`exact_variety_step`) while its dense Gram side is at most this
#: (sigma(8, 2) = 45: 4 views with point regions; measured on one CPU: 0.1 s at 3 views, 0.3-0.9 s at 4; it runs only
#: where the plan did not certify, within the point's time limit).
EXACT_VARIETY_MAX_SIDE = DENSE_MAX_SIDE
#: :func:`exact_variety_views_step` up to this many views (it certified none of five in-plane points at N = 10)
EXACT_VARIETY_VIEWS_MAX = 8
#: ... and up to this many where the centres are collinear (a straight drive, a rectified rig; review 31a).
#: Measured (benchmarks/RESULTS.md, wave 31): forward motion 6 / 6 points of 9-12 views certified in 0.7-1.8 s and
#: numerical failures at 14-16 views (~2 s); rectified rigs 5 / 6 of 9-12 views (2.6-5.2 s), 7-10 s at 14-16
EXACT_VARIETY_COLLINEAR_MAX = 12


@dataclass(frozen=True)
class Step:
    method: Method            # the formulation's constraints (Corollary 1: epipolar; Theorem 1: minors)
    delta: int
    formulation: str          # "dense" or "views"
    reported: Method | None = None   # the method a result of this step is reported under (default: ``method``)

    @property
    def result_method(self) -> Method:
        return self.reported or self.method


def _formulation(options: TriangulationOptions, method: Method, delta: int, n_views: int, n_vars: int) -> str:
    if delta <= 2 or options.sparsity == Sparsity.DENSE or options.multiplier == Multiplier.FREE:
        return "dense"      # (a free SOS multiplier q exists for dense certificates only; the options refuse 'views')
    if n_views <= 2 or (n_views == 3 and method == Method.THEOREM1):
        return "dense"      # one clique holds every view: the views add a redundant block (asked for too: Theorem 1
        #                     at three views of wrong matches, 'views' ended solver_failed after 1.1 s, dense 23 ms)
    if options.sparsity == Sparsity.CLIQUES:          # the view cliques ("views")
        return "views"
    # Corollary 1 with three views: the band's cliques are view pairs, and the size rule decides (measured,
    # benchmarks/RESULTS.md "issue #22": mixed 16 px regions, dense 5.3 s and 16.9 s, views 0.6 s and 1.2 s,
    # same certified values)
    if method == Method.THEOREM1 and n_views > THEOREM1_DENSE_MAX_VIEWS:
        return "views"
    return "dense" if sigma(n_vars, delta // 2) <= DENSE_MAX_SIDE else "views"


def degree_plan(options: TriangulationOptions, n_views: int, n_vars: int, delta_min: int) -> list[Step]:
    """The steps for a problem with ``n_views`` views and ``n_vars`` polynomial variables (module docstring).
    Raises ValueError for a ``delta`` below ``delta_min``."""
    method = options.explicit_method
    if options.delta is not None and options.delta < delta_min:
        raise ValueError(f"delta must be even and >= delta_min = {delta_min} for this problem, got {options.delta}")
    if method is None:
        first = options.delta if options.delta is not None else max(delta_min, 2)
        last = options.max_delta if options.max_delta is not None else max(first, 4)
        method = Method.COROLLARY1
    else:
        first = options.delta if options.delta is not None else delta_min
        last = options.max_delta if options.max_delta is not None else (
            options.delta if options.delta is not None else delta_min + 2)
    if last < first:
        raise ValueError(f"max_delta ({last}) is below delta ({first})")
    steps = []
    if method == Method.THEOREM1 and options.delta is None and first > 2:
        # Corollary 1's epipolar constraints are Theorem 1's two-view minors (up to a constant factor), so its
        # degree-2 certificate is a Theorem 1 certificate at degree 2 (zero multipliers on the 3- and 4-view
        # minors): tried first, in milliseconds, before the degree-4 programs
        steps.append(Step(Method.COROLLARY1, 2, "dense", reported=Method.THEOREM1))
    for d in range(first, last + 1, 2):
        form = _formulation(options, method, d, n_views, n_vars)
        steps.append(Step(method, d, form))
        small = sigma(n_vars, d // 2) <= DENSE_FALLBACK_SIDE or n_views <= 3   # three views: dense as before
        if form == "views" and options.sparsity == Sparsity.AUTO and small \
                and not (method == Method.THEOREM1 and n_views > THEOREM1_DENSE_MAX_VIEWS):
            steps.append(Step(method, d, "dense"))
    return steps


def exact_variety_step(options: TriangulationOptions, n_views: int, n_vars: int, plan: list[Step]) -> Step | None:
    """The step after an uncertified ``plan`` (module docstring): Theorem 1 at delta = 4, dense, with
    ``method="auto"`` and ``sparsity`` auto or dense, when the plan reaches delta = 4, the problem has at least 3
    views (two views: Corollary 1's one epipolar relation is Theorem 1's only minor, up to a constant) and the dense
    Gram side sigma(n_vars, 2) is at most :data:`EXACT_VARIETY_MAX_SIDE`; None otherwise."""
    if not plan or max(s.delta for s in plan) < 4 or not exact_variety_applies(options, n_views, n_vars):
        return None
    return Step(Method.THEOREM1, 4, "dense")


def exact_variety_views_step(options: TriangulationOptions, n_views: int, n_vars: int,
                             collinear: bool = False) -> Step | None:
    """The exact-variety step beyond the dense one's reach, for a point whose Corollary 1 plan stopped at the
    ceiling of coplanar centres (:func:`tritools.solve.coplanar.futile_after`): Theorem 1 at delta = 4 in the view
    clique form (epipolar pairs + the minors of a chain of view triples, whose trilinear relations exclude the
    plane's component) for 5 to :data:`EXACT_VARIETY_VIEWS_MAX` views (:data:`EXACT_VARIETY_COLLINEAR_MAX` where
    the centres are ``collinear``: a pencil of such planes) with point regions (n_vars = 2N), with
    ``method="auto"`` and ``sparsity="auto"``; None otherwise.  Cheap (0.3-0.9 s) but numerically fragile there:
    certified about one point in five, the others stay not_certified with their valid bounds
    (benchmarks/RESULTS.md, "Coplanar camera centres")."""
    if options.explicit_method is not None or options.sparsity != Sparsity.AUTO or n_vars != 2 * n_views:
        return None
    if not 5 <= n_views <= (EXACT_VARIETY_COLLINEAR_MAX if collinear else EXACT_VARIETY_VIEWS_MAX) \
            or options.max_delta is not None and options.max_delta < 4:
        return None
    return Step(Method.THEOREM1, 4, "views")


def exact_variety_applies(options: TriangulationOptions, n_views: int, n_vars: int) -> bool:
    """Whether :func:`exact_variety_step` may run on such a problem (its rule without the plan's degrees)."""
    if options.explicit_method is not None or options.sparsity == Sparsity.CLIQUES or n_views < 3:
        return False
    return sigma(n_vars, 2) <= EXACT_VARIETY_MAX_SIDE


def delta_min(method: Method, n_views: int) -> int:
    """delta_min of a triangulation program: region polynomials and epipolar constraints are quadratic; Theorem
    1's minors are quadratic for two views and of degree 3-4 beyond (SPEC §3)."""
    return 2 if method == Method.COROLLARY1 or n_views == 2 else 4


def batch_steps(opts: TriangulationOptions) -> tuple[bool, bool]:
    """(verification batch, delta = 2 SDP batch) applicable under these options: the plan starts with Corollary 1
    (or auto) at delta = 2 with normalisation; the SDP batch also needs the default multiplier, the image form
    and the automatic back-end (``backend=None`` or ``"auto"``: :mod:`tritools.solve.settings`)."""
    first_is_cor1_d2 = opts.method in (MethodChoice.AUTO, MethodChoice.COROLLARY1) and opts.delta in (None, 2) \
        and opts.normalize
    verify = first_is_cor1_d2 and opts.path == SolvePath.AUTO
    sdp = first_is_cor1_d2 and opts.multiplier == Multiplier.FIXED and opts.form == GramForm.IMAGE \
        and opts.backend in (None, "auto")
    return verify, sdp


def last_delta(opts: TriangulationOptions) -> int:
    """The last degree of the plan of a batch (:func:`degree_plan`'s rule without the problem's delta_min)."""
    if opts.max_delta is not None:
        return opts.max_delta
    if opts.method == MethodChoice.AUTO:
        return max(opts.delta or 2, 4)
    return opts.delta if opts.delta is not None else 4
