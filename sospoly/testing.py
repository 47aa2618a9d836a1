"""Scripted conic back-ends for testing the strategy logic around a solver (``import sospoly.testing``).

As MathOptInterface's ``MockOptimizer`` (used by SumOfSquares.jl's tests), a fake back-end answers from a
script instead of solving, and records what it was asked, so that a test can drive every branch of a
caller's strategy -- the :class:`~sospoly.SolveStatus` mapping, retry chains, budgets, the decision on the
bounds -- in milliseconds and deterministically:

* :class:`FakeBackend` speaks the back-end protocol of :func:`sospoly.solvers.get_backend`
  (``solve(problem, accept=None, retry=True, deadline=None) -> ConicSolution``): each call takes the next
  :class:`Canned` answer of its script and returns it as one attempt.  Pass it wherever a back-end is
  accepted (``sospoly.solve_psatz(..., backend=fake)``, ``sospoly.minimize(..., backend=fake)``,
  ``tritools.triangulate(..., backend=fake)``).
* :class:`FakeClarabel` is :class:`~sospoly.solvers.ClarabelBackend` with its *single solver call*
  scripted: each attempt of Clarabel's real retry chain (which settings, how many attempts, when the
  chain stops) takes the next answer.

A canned answer is a raw status (:class:`~sospoly.solvers.RawStatus`: what the solver said) and an iterate:
none, a given vector, :data:`REFERENCE` (the answer of a real Clarabel solve of the same program: a true
certificate relabelled with the canned status), or a function of the program such as :func:`suboptimal`
(the reference moved to a worse objective: a valid but weaker certificate) and :func:`overstated`
(moved to a better objective than the optimum: a solver that lies).  Whatever the script says, the
a-posteriori checks of :func:`sospoly.solve_conic` and the rigorous bounds still judge the numbers; that is
what these fakes let a test show.

Example -- a solver error in the image form; :func:`sospoly.minimize` retries in the kernel form, where the
fake returns a true certificate::

    import sospoly
    from sospoly.solvers import RawStatus
    from sospoly.testing import REFERENCE, Canned, FakeBackend

    x, = sospoly.variables("x")
    fake = FakeBackend([Canned(RawStatus.FAILED), Canned(RawStatus.SOLVED, REFERENCE)])
    res = sospoly.minimize((x - 1) ** 2 + 2, degree=2, backend=fake)
    assert res.optimal and [c.problem.form.value for c in fake.calls] == ["image", "kernel"]
"""
from __future__ import annotations

import enum
import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .budget import Deadline
from .lowering.conic import ConicProblem
from .solvers.backends import Attempt, ClarabelBackend, ConicSolution, RawStatus
from .tolerances import DEFAULT_TOLERANCES

__all__ = ["Iterate", "REFERENCE", "UNTIL_DEADLINE", "Canned", "FakeCall", "FakeBackend", "FakeClarabel",
           "ScriptExhausted", "reference_solution", "suboptimal", "overstated"]

log = logging.getLogger(__name__)


class Iterate(enum.Enum):
    """Iterates a :class:`Canned` answer can name instead of giving a vector."""
    REFERENCE = "reference"          #: the primal-dual answer of a real Clarabel solve of the same program


#: the iterate of a real Clarabel solve of the program asked about (:func:`reference_solution`).
REFERENCE = Iterate.REFERENCE
#: ``Canned(delay=UNTIL_DEADLINE)``: the fake sleeps until the call's deadline has passed (none: no sleep).
UNTIL_DEADLINE = float("inf")


class ScriptExhausted(AssertionError):
    """A fake back-end was called more often than its script allows (an unexpected solve)."""


@dataclass(frozen=True)
class Canned:
    """One scripted answer.

    Parameters
    ----------
    status : what the solver says (:class:`~sospoly.solvers.RawStatus` or its value)
    x : the primal iterate: None (no iterate, as after a solver error), a vector of the program's
        ``n_cols``, :data:`REFERENCE`, or ``f(problem) -> vector``
    solver_status : the solver's own word for it (default: the raw status' value), e.g. ``"MaxIterations"``
    iterations : reported iterations
    delay : seconds the call really takes (wall time: time limits are measured on the clock), or
        :data:`UNTIL_DEADLINE`
    """
    status: RawStatus | str
    x: object = None
    solver_status: str = ""
    iterations: int = 1
    delay: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", RawStatus(self.status))
        if not (isinstance(self.x, (Iterate, np.ndarray, list, tuple)) or self.x is None or callable(self.x)):
            raise TypeError(f"Canned.x must be None, a vector, REFERENCE or a function of the problem, got "
                            f"{type(self.x).__name__}")
        if not self.delay >= 0:
            raise ValueError(f"Canned.delay must be >= 0 seconds, got {self.delay!r}")

    @property
    def label(self) -> str:
        return self.solver_status or self.status.value


@dataclass(frozen=True)
class FakeCall:
    """What a fake back-end was asked, and what it answered.

    ``accepted``: the caller's a-posteriori check (``accept(x, z)``) on the canned iterate, None when there
    was no iterate or no check; ``label`` / ``overrides``: the retry-chain step (:class:`FakeClarabel`)."""
    problem: ConicProblem
    answer: Canned
    retry: bool | None
    deadline_left: float | None
    accepted: bool | None
    label: str = "fake"
    overrides: tuple = ()


def reference_solution(problem: ConicProblem) -> ConicSolution:
    """The answer of a real Clarabel solve of ``problem`` (default tolerances; a tiny program takes
    milliseconds): the certificate a canned status is attached to by :data:`REFERENCE`."""
    return ClarabelBackend(DEFAULT_TOLERANCES).solve(problem)


def _moved(by: float) -> Callable[[ConicProblem], np.ndarray]:
    """The reference iterate moved along the cost vector q so that the conic objective q^T x (always minimised)
    grows by ``by``: a worse objective for ``by > 0``, a better one than the optimum for ``by < 0``."""
    def iterate(problem: ConicProblem) -> np.ndarray:
        ref = reference_solution(problem)
        if ref.x is None:
            raise ValueError(f"no reference iterate to move: the reference solve ended {ref.raw_status.value}")
        q = np.asarray(problem.q, float)
        return ref.x + (by / float(q @ q)) * q
    return iterate


def suboptimal(by: float) -> Callable[[ConicProblem], np.ndarray]:
    """An iterate whose objective is ``|by|`` worse than the reference's (user units when the objective's
    coefficient vector has unit norm, as the level c of a Positivstellensatz program, whose lower bound is then
    smaller by ``|by|``).  There, c enters u = f - c q with q SOS, so the iterate is a still-valid weaker
    certificate."""
    return _moved(abs(by))


def overstated(by: float) -> Callable[[ConicProblem], np.ndarray]:
    """An iterate whose objective is ``|by|`` better than the optimum (as :func:`suboptimal`): a solver that
    lies.  Its Gram matrices lose positive semidefiniteness by about ``|by|`` (the a-posteriori check or the
    rigorous margin must catch it)."""
    return _moved(-abs(by))


class _Script:
    """The canned answers in order; ``then`` answers every call after them (None: an unexpected call raises
    :class:`ScriptExhausted`)."""

    def __init__(self, script: Sequence[Canned | RawStatus | str], then: Canned | None):
        self.answers = [a if isinstance(a, Canned) else Canned(a) for a in script]
        self.then = then if then is None or isinstance(then, Canned) else Canned(then)
        self.position = 0

    def next(self, problem: ConicProblem) -> Canned:
        if self.position < len(self.answers):
            self.position += 1
            return self.answers[self.position - 1]
        if self.then is None:
            raise ScriptExhausted(f"fake back-end called {self.position + 1} times, its script has "
                                  f"{len(self.answers)} answers (program with {problem.n_cols} columns)")
        return self.then


def _sleep(delay: float, deadline: Deadline | None) -> None:
    if delay == UNTIL_DEADLINE:
        left = None if deadline is None else deadline.remaining()
        delay = 0.0 if left is None else max(left, 0.0) + 1e-3
    if delay > 0:
        time.sleep(delay)


def _iterate(answer: Canned, problem: ConicProblem):
    """(x, z) of a canned answer: z from the reference for :data:`REFERENCE`, zeros otherwise."""
    if answer.x is None:
        return None, None
    if answer.x is REFERENCE:
        ref = reference_solution(problem)
        return ref.x, ref.z
    x = answer.x(problem) if callable(answer.x) else answer.x
    x = np.asarray(x, float)
    if x.shape != (problem.n_cols,):
        raise ValueError(f"canned iterate has shape {x.shape}, the program has {problem.n_cols} columns")
    return x, np.zeros(problem.n_rows)


def _check(accept, x, z) -> bool | None:
    return None if accept is None or x is None else bool(accept(x, z))


class FakeBackend:
    """A back-end that answers from ``script``: one :class:`Canned` per ``solve`` call (the back-end protocol of
    :func:`sospoly.solvers.get_backend`), then ``then`` for every further call (default: an extra call raises
    :class:`ScriptExhausted`).  ``calls`` records every call (:class:`FakeCall`)."""

    def __init__(self, script: Sequence[Canned | RawStatus | str] = (), *, then: Canned | None = None,
                 name: str = "fake"):
        self._script = _Script(script, then)
        self.name = name
        self.calls: list[FakeCall] = []

    def __repr__(self) -> str:
        return f"FakeBackend({self.name!r})"

    __str__ = __repr__

    def solve(self, problem: ConicProblem, accept=None, retry: bool = True,
              deadline: Deadline | None = None) -> ConicSolution:
        """The next canned answer as a :class:`~sospoly.solvers.ConicSolution` of one attempt."""
        answer = self._script.next(problem)
        left = None if deadline is None else deadline.remaining()
        t0 = time.perf_counter()
        _sleep(answer.delay, deadline)
        x, z = _iterate(answer, problem)
        accepted = _check(accept, x, z)
        self.calls.append(FakeCall(problem, answer, retry, left, accepted, self.name))
        log.debug("fake back-end call %d: %s (accepted: %s)", len(self.calls), answer.label, accepted)
        att = Attempt(self.name, answer.status, answer.label, answer.iterations, time.perf_counter() - t0)
        obj = None if x is None else float(np.asarray(problem.q, float) @ x)
        return ConicSolution(answer.status, x, z, obj, obj, (att,))


@dataclass(frozen=True)
class _RawAnswer:
    """The fields of a Clarabel solution that :meth:`ClarabelBackend.solve` reads."""
    x: np.ndarray
    z: np.ndarray
    obj_val: float
    obj_val_dual: float


class FakeClarabel(ClarabelBackend):
    """:class:`~sospoly.solvers.ClarabelBackend` whose solver calls answer from ``script``: its retry chain
    (which settings, in which order, when it stops) is the real one.  ``calls`` records every attempt with
    its chain label and settings overrides.  A canned ``FAILED`` without an iterate is an exception inside
    the solver (no solution object); any other status without one returns NaN vectors, as Clarabel does."""

    name = "fake-clarabel"

    def __init__(self, script: Sequence[Canned | RawStatus | str] = (), *, then: Canned | None = None,
                 tolerances=DEFAULT_TOLERANCES, **settings):
        super().__init__(tolerances, **settings)
        self._script = _Script(script, then)
        self.calls: list[FakeCall] = []

    def solve_once(self, problem: ConicProblem, label="default", overrides=None, deadline: Deadline | None = None,
                   first_seconds: float = 0.0, stop_by: Deadline | None = None):
        """One scripted attempt: (raw answer or None, :class:`~sospoly.solvers.Attempt`); ``stop_by`` unused (a
        scripted answer has no iterations to stop)."""
        answer = self._script.next(problem)
        left = None if deadline is None else deadline.remaining()
        t0 = time.perf_counter()
        _sleep(answer.delay, deadline)
        x, z = _iterate(answer, problem)
        self.calls.append(FakeCall(problem, answer, None, left, None, label, tuple(sorted((overrides or {}).items()))))
        seconds = time.perf_counter() - t0
        att = Attempt(label, answer.status, answer.label, answer.iterations, seconds, seconds)
        if x is None and answer.status == RawStatus.FAILED:
            return None, att                    # as after an exception (a panic): no solution object at all
        if x is None:                           # Clarabel always returns vectors; here without a usable iterate
            x, z = np.full(problem.n_cols, np.nan), np.full(problem.n_rows, np.nan)
        obj = float(np.asarray(problem.q, float) @ x)
        return _RawAnswer(x, z, obj, obj), att
