"""Bounded resources: the size of a program before it is built, and the budget it must fit.

Every entry point that builds an SOS program (:func:`sospoly.minimize`, :func:`sospoly.solve_psatz`,
the compiled structures, ``tritools.triangulate``) first *estimates* the program from the shape of
its certificate (Gram bases, multiplier supports) with :func:`estimate_size`, compares the estimate
with a :class:`Budget`, and refuses -- with a :class:`BudgetExceeded` error naming the estimate and
the way out, or a result with status ``budget_exceeded`` -- instead of letting a solver allocate
terabytes in native code.  Time is bounded the same way: ``Budget.time_limit`` becomes Clarabel's
``time_limit`` setting and a deadline checked between the iterations of the interior-point method
and between the steps of a bisection, so a solve returns with status ``time_limit`` instead of
running for minutes.  What Clarabel cannot interrupt -- its set-up and one iteration -- is predicted from
the program's size (:class:`ClarabelTimeModel`): an attempt that cannot finish it before the deadline is
not started, and Clarabel's ``time_limit`` is the time left less that start.  A signal whose Python handler raises
(Ctrl-C's ``KeyboardInterrupt``, a SIGTERM handler) ends a Clarabel solve at its next iteration, through
Clarabel's termination callback, and is raised again once the solve has returned
(:func:`sospoly.solvers.interrupt.solve_interruptibly`).

Memory model (8-byte floats; an estimate, deliberately on the safe side):

* Clarabel factorises a KKT system whose PSD-cone blocks are dense in svec space: a Gram block of
  side s contributes L^2 entries, L = s (s + 1) / 2, to the KKT matrix and its LDL factor (values and
  indices), :data:`CLARABEL_ENTRY_COPIES` floats per entry, and the largest block once more to the
  solver's dense work arrays, :data:`CLARABEL_LARGEST_BLOCK_COPIES` floats per entry weighted by that
  block's share w = L_max^2 / sum_k L_k^2 of all entries, besides a few copies of the constraint matrix.
  Measured peaks (Theorem 1 with ellipses at delta = 4, Gram blocks of side 91, w ~ 1): 3 views 0.91 GB
  (estimate 0.98), 4 views 0.94 GB (1.33), 5 views 1.25 GB (1.68).  Programs of many blocks (the views
  sparsity of benchmarks/manyview.py, large setting, seed 2; Clarabel's peak RSS above its start, issue
  #22): N = 16 / 20 / 24 / 30 used 336 / 446 / 639 / 827 MiB, 1.6-1.7 floats per entry of the estimate's
  blocks; the unweighted largest-block term estimated 588 / 871 / 1408 / 2223 MiB (1.7-2.7x, N = 30 refused
  by the 2 GiB default), the weighted one 524 / 718 / 1099 / 1679 MiB (1.6-2.0x, still above every peak).
* Clarabel decomposes a PSD block along the aggregate sparsity of its rows: where the dense estimate does not
  fit, a program lowered in the image form is sized again on the chordal cliques of its Gram blocks' structurally
  non-zero entries (:mod:`sospoly.certificates.sizing`; a degree-2 program of 30 views of mixed regions: 2.1 GiB
  dense, 0.37 GiB on its cliques, 0.26 GB measured).
* The batched interior-point method (:mod:`sospoly.solvers.ipm`) holds, per PSD block of side s,
  the m full s x s matrices of the columns (m = number of decision columns) and the m x m Schur
  complement.
* The estimate (:attr:`ProgramSize.bytes`) is the peak of what may run: Clarabel always (it is every
  back-end's fallback), and the interior-point method too where the ``auto`` back-end picks it (one
  Gram block, within its memory cap).

The budget is bounded by the process's own limit too: under an address-space limit (``RLIMIT_AS``,
``ulimit -v``) a native allocation beyond it aborts the interpreter, so :meth:`ProgramSize.exceeds`
also compares the estimate with the address space left (:func:`address_space_available`), and the
Clarabel back-end checks it again before it is called.
"""
from __future__ import annotations

import contextlib
import contextvars
import math
import numbers
import os
import time
from dataclasses import dataclass

__all__ = ["Budget", "DEFAULT_TIME_LIMIT", "DEFAULT_BUDGET", "UNLIMITED", "ProgramSize", "estimate_size",
           "gram_block_exceeds",
           "BudgetExceeded", "Deadline",
           "as_budget", "TimeLimitReached", "deadline_scope", "check_deadline", "check_time_left", "deadline_passed",
           "active_deadline",
           "cpu_share", "MIN_CPU_SHARE", "address_space_available",
           "memory_room", "CLARABEL_ENTRY_COPIES", "CLARABEL_LARGEST_BLOCK_COPIES", "AUTO_IPM_MAX_BYTES",
           "ADDRESS_SPACE_SHARE", "ClarabelTimeModel", "CLARABEL_TIME_MODEL"]


#: the one default time limit of both packages, in seconds: of one :func:`sospoly.minimize` /
#: :func:`sospoly.solve_psatz` call, and of one point in tritools (``time_limit`` is per point there, a batch's
#: whole-call limit is the separate ``total_time_limit``).  One minute: long enough for every program within the
#: default memory budget on a 2-core machine, short enough that no default call runs for minutes.
DEFAULT_TIME_LIMIT = 60.0


@dataclass(frozen=True)
class Budget:
    """Resources one solve may use.

    ``time_limit``: seconds per call (``None``: no limit); ``max_bytes``: the largest estimated
    memory of one program (``None``: no limit); ``max_gram_side``: the largest Gram matrix side
    (a structural cap that also stops absurd degrees before any polynomial is expanded).
    """

    time_limit: float | None = DEFAULT_TIME_LIMIT
    max_bytes: float | None = 4 * 2 ** 30
    max_gram_side: int = 5000

    def __post_init__(self) -> None:
        for name in ("time_limit", "max_bytes"):
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, numbers.Real) or not v > 0
                                  or math.isnan(v)):
                raise ValueError(f"Budget.{name} must be a positive number or None, got {v!r}")
        v = self.max_gram_side
        if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 1:
            raise ValueError(f"Budget.max_gram_side must be a positive integer, got {v!r}")

    def deadline(self) -> Deadline:
        return Deadline.after(self.time_limit)


#: the default budget: :data:`DEFAULT_TIME_LIMIT` (one minute) and 4 GiB per solve, Gram matrices of side <= 5000.
DEFAULT_BUDGET = Budget()
#: no time or memory limit (the Gram side cap stays: it only refuses programs no machine holds).
UNLIMITED = Budget(time_limit=None, max_bytes=None)


def as_budget(value) -> Budget:
    """The one input check of every ``budget=`` argument (None -> :data:`DEFAULT_BUDGET`)."""
    if value is None:
        return DEFAULT_BUDGET
    if not isinstance(value, Budget):
        raise TypeError(f"budget must be a sospoly.Budget, got {type(value).__name__}")
    return value


@dataclass(frozen=True)
class Deadline:
    """A point in time (``time.monotonic``) after which work stops; ``None`` end: never.  ``span``: the time limit
    it stands for (seconds; None: unknown), so that work allowed past it can be a share of the limit
    (:meth:`overrun`)."""

    end: float | None
    span: float | None = None

    @classmethod
    def after(cls, seconds: float | None, span: float | None = None) -> Deadline:
        """The deadline ``seconds`` from now, standing for a limit of ``span`` seconds (default ``seconds``)."""
        if seconds is None:
            return cls(None)
        return cls(time.monotonic() + float(seconds), float(seconds) if span is None else float(span))

    def remaining(self) -> float | None:
        return None if self.end is None else max(0.0, self.end - time.monotonic())

    @property
    def expired(self) -> bool:
        return self.end is not None and time.monotonic() >= self.end

    def overrun(self) -> float:
        """The time since the deadline passed as a share of its ``span`` (0 before it, or without an end; inf past
        it without a span)."""
        if self.end is None:
            return 0.0
        late = time.monotonic() - self.end
        if late <= 0.0:
            return 0.0
        return late / self.span if self.span else float("inf")


class TimeLimitReached(RuntimeError):
    """The active deadline (:func:`deadline_scope`) passed while a program was built, assembled or
    sized; entry points turn it into status ``time_limit``."""


_ACTIVE_DEADLINE: contextvars.ContextVar = contextvars.ContextVar("sospoly_deadline", default=None)


@contextlib.contextmanager
def deadline_scope(deadline: Deadline | None):
    """Make ``deadline`` the one :func:`check_deadline` tests inside the block (an enclosing scope's
    earlier deadline stays in force): the build loops of sospoly and tritools check it without every
    function taking a ``deadline`` argument."""
    outer = _ACTIVE_DEADLINE.get()
    if deadline is None or deadline.end is None or (outer is not None and outer.end is not None
                                                     and outer.end <= deadline.end):
        deadline = outer
    token = _ACTIVE_DEADLINE.set(deadline)
    try:
        yield deadline
    finally:
        _ACTIVE_DEADLINE.reset(token)


#: the machine's cores, read once (``os.cpu_count`` costs ~6 us, a few per cent of a single triangulation's checks)
_CORES = os.cpu_count() or 1
#: the smallest share of a core :func:`cpu_share` reports (a load average above 16x the cores is not extrapolated)
MIN_CPU_SHARE = 1.0 / 16


def cpu_share() -> float:
    """The share of one core this process can expect now: cores / the 1-minute load average when the machine is
    over-committed, else 1 (and 1 where the load average is not available).  Deadlines are wall-clock: a step that
    cannot be interrupted takes its CPU time over this share in wall time, which the callers that predict a step's
    time before starting it (e.g. :func:`tritools.solve.fastpath.fits`) divide by."""
    try:
        load = os.getloadavg()[0]
    except (OSError, AttributeError):
        return 1.0
    return 1.0 if not load > _CORES else max(MIN_CPU_SHARE, _CORES / load)


def active_deadline() -> Deadline | None:
    """The deadline :func:`check_deadline` tests (the innermost :func:`deadline_scope`'s), None outside any."""
    return _ACTIVE_DEADLINE.get()


def deadline_passed() -> bool:
    """Has the active deadline (:func:`deadline_scope`) passed?  O(1): one clock read.  Heuristics whose every
    partial answer is valid (the search for minimiser candidates) stop with what they have when it is True;
    the build loops raise instead (:func:`check_deadline`)."""
    d = _ACTIVE_DEADLINE.get()
    return d is not None and d.end is not None and time.monotonic() >= d.end


def check_deadline(what: str = "building the program") -> None:
    """Raise :class:`TimeLimitReached` when the active deadline has passed (:func:`deadline_passed`)."""
    if deadline_passed():
        raise TimeLimitReached(f"time limit reached while {what}")


def check_time_left(seconds: float, what: str) -> None:
    """:func:`check_deadline`, and raise :class:`TimeLimitReached` too when less of the active deadline is left
    than ``seconds`` of CPU time take at the share of a core this process can expect (:func:`cpu_share`): a
    step that cannot be interrupted is not started when it cannot end before the deadline."""
    check_deadline(what)
    d = _ACTIVE_DEADLINE.get()
    if d is not None and d.end is not None and seconds > (d.end - time.monotonic()) * cpu_share():
        raise TimeLimitReached(f"time limit reached: {what} (~{seconds:.2g} s of CPU) cannot end before it")


#: floats per svec-entry pair (L^2) of every PSD block in Clarabel: the KKT block and its LDL factor.
CLARABEL_ENTRY_COPIES = 2.5
#: floats per svec-entry pair of the largest PSD block once more, weighted by its share of all entries:
#: Clarabel's dense work arrays (module docstring).
CLARABEL_LARGEST_BLOCK_COPIES = 4.5
#: the interior-point method's working set above which the ``auto`` back-end goes to Clarabel directly
#: (the rule of :class:`sospoly.solvers.backends.AutoBackend`).
AUTO_IPM_MAX_BYTES = 1.5 * 2 ** 30
#: share of the address space left under ``RLIMIT_AS`` that one program may use (the rest: the
#: interpreter's own growth, solver work arrays, fragmentation).
ADDRESS_SPACE_SHARE = 0.7


def address_space_available() -> float | None:
    """Bytes of address space left under the soft ``RLIMIT_AS`` (None without a limit or off Linux):
    the limit minus the current virtual size (``/proc/self/statm``)."""
    try:
        import resource
        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
        if soft == resource.RLIM_INFINITY or soft < 0:
            return None
        with open("/proc/self/statm", "rb") as fh:
            pages = int(fh.read().split()[0])
        return max(0.0, float(soft) - pages * float(resource.getpagesize()))
    except (ImportError, OSError, ValueError, IndexError):
        return None


def memory_room(budget: Budget | None) -> tuple[float | None, str]:
    """The most one program may use: the budget's ``max_bytes`` or, when smaller,
    :data:`ADDRESS_SPACE_SHARE` of the address space left; with the name of the binding limit."""
    limit = None if budget is None else budget.max_bytes
    room = address_space_available()
    if room is not None and (limit is None or ADDRESS_SPACE_SHARE * room < limit):
        return ADDRESS_SPACE_SHARE * room, "the address space left under the process's limit (RLIMIT_AS)"
    return limit, "the memory budget"


def gram_block_exceeds(side: int, budget: Budget | None) -> str | None:
    """Why no program holding a PSD block of ``side`` fits ``budget`` (None when one might): the side beyond
    ``max_gram_side``, or the block's own share of Clarabel's memory (``CLARABEL_ENTRY_COPIES`` floats per svec
    entry pair, L = side (side + 1) / 2) beyond the room of :func:`memory_room`.  A floor of
    :func:`estimate_size` for every program with this block (more blocks or columns only add to it), computed
    from the side alone: a caller refuses a program before building its polynomials (dense certificates of many
    variables take seconds and gigabytes to build before :class:`CertificateShape.size` sees them)."""
    side = int(side)
    if budget is None:
        return None
    if side > budget.max_gram_side:
        return f"a Gram matrix of side {side} exceeds the limit {budget.max_gram_side}"
    L = side * (side + 1) // 2
    floor = 8.0 * CLARABEL_ENTRY_COPIES * float(L) * float(L)
    room, what = memory_room(budget)
    if room is not None and floor > room:
        return (f"a program with a Gram block of side {side} needs at least {_human(floor)} for Clarabel's KKT "
                f"system, beyond {what} {_human(room)}")
    return None


@dataclass(frozen=True)
class ProgramSize:
    """Estimated size of an SOS program (see the module docstring for the memory model)."""

    gram_sides: tuple
    n_columns: int          # decision columns of the image form (an upper bound of N_LMIVAR)
    n_rows: int
    clarabel_bytes: float
    ipm_bytes: float

    @property
    def max_gram_side(self) -> int:
        return max(self.gram_sides, default=0)

    @property
    def bytes(self) -> float:
        """Estimated peak: Clarabel's, or the interior-point method's where the ``auto`` back-end runs it
        first (one Gram block within :data:`AUTO_IPM_MAX_BYTES`)."""
        ipm_first = len(self.gram_sides) == 1 and self.ipm_bytes <= AUTO_IPM_MAX_BYTES
        return max(self.clarabel_bytes, self.ipm_bytes) if ipm_first else self.clarabel_bytes

    def describe(self) -> str:
        sides = sorted(self.gram_sides, reverse=True)
        shown = ", ".join(map(str, sides[:4])) + (f", ... ({len(sides)} blocks)" if len(sides) > 4 else "")
        return (f"Gram blocks of side {shown}; ~{self.n_columns} decision columns; "
                f"estimated memory {_human(self.bytes)}")

    def exceeds(self, budget: Budget) -> str | None:
        """Why this program does not fit ``budget`` (None when it fits)."""
        if self.max_gram_side > budget.max_gram_side:
            return (f"a Gram matrix of side {self.max_gram_side} exceeds the limit {budget.max_gram_side} "
                    f"({self.describe()})")
        room, what = memory_room(budget)
        if room is not None and self.bytes > room:
            return f"{self.describe()} exceeds {what} {_human(room)}"
        return None


def _human(n: float) -> str:
    units = ("B", "KiB", "MiB", "GiB", "TiB")
    k = 0
    while n >= 1024 and k < len(units) - 1:
        n, k = n / 1024.0, k + 1
    return f"{n:.3g} {units[k]}"


def estimate_size(gram_sides, n_free: int = 0, n_equality_rows: int = 0) -> ProgramSize:
    """Estimate a program from its Gram block sides (every SOS constraint's and SOS multiplier's),
    ``n_free`` free decision scalars (c, coefficients of free multipliers) and ``n_equality_rows``
    linear equality rows.  Works on Python integers, so astronomically large programs are measured
    without overflow."""
    sides = tuple(int(s) for s in gram_sides)
    L = [s * (s + 1) // 2 for s in sides]
    n_cols = int(n_free) + sum(L)              # alphas/Gram entries: at most every svec entry
    n_rows = int(n_equality_rows) + sum(L)
    nnz = 3 * n_rows + 2 * n_cols
    entries = float(sum(x * x for x in L))
    largest = float(max(L, default=0)) ** 2
    share = largest / entries if entries > 0 else 0.0        # the largest block's share w (module docstring)
    clarabel = 8.0 * (CLARABEL_ENTRY_COPIES * entries + CLARABEL_LARGEST_BLOCK_COPIES * largest * share) \
        + 80.0 * nnz
    ipm = 8.0 * (2.0 * n_cols * float(sum(s * s for s in sides)) + float(n_cols) ** 2)
    return ProgramSize(sides, n_cols, n_rows, clarabel, ipm)


class ClarabelTimeModel:
    """Seconds Clarabel needs before its time limit can act: set-up (KKT assembly, symbolic and numeric
    factorisation), the initial point and one interior-point iteration -- none of which Clarabel interrupts
    (its ``time_limit`` is checked between iterations).

    Time model, in the sizes of the memory model (L = s (s + 1) / 2 per PSD block of side s; the dense
    svec blocks dominate the KKT factorisation)::

        t_first = scale * (FIXED + PER_ENTRY_FIRST * sum_k L_k^2 + PER_ROW * n_rows)
        t_iter  = scale * (FIXED + PER_ENTRY_ITER  * sum_k L_k^2 + PER_ROW * n_rows)

    Calibrated on Theorem 1 programs with mixed regions (3-11 views, delta = 4; sum L^2 = 5e6 .. 2e7) on
    the shared 2-core machine under load: set-up + first iteration 3.3-10 s, 1e-7 .. 1.9e-7 s per entry
    and iteration.  ``scale`` adapts to the machine: every Clarabel call reports its measured set-up and
    per-iteration times (:meth:`observe`) and the model follows their ratio to the prediction (at once
    when slower, a quarter of the way when faster, clipped to [1/2, 4]), so a loaded machine is measured, not
    guessed, and a fast one never makes the model optimistic.
    """

    FIXED = 0.01
    PER_ENTRY_FIRST = 5e-7
    PER_ENTRY_ITER = 2e-7
    PER_ROW = 2e-6
    SCALE_RANGE = (0.5, 4.0)
    MIN_CALIBRATED = 0.25
    GROWTH = 0.5

    def __init__(self) -> None:
        self.scale = 1.0
        self.reference_entries = math.inf       # the smallest program that lowered the scale

    def scale_for(self, entries: float) -> float:
        """The scale of a program of ``entries`` = sum_k L_k^2 (class docstring): ``scale`` at or above 1 and up
        to ``reference_entries``, beyond it the optimism shrinks as (entries / reference)^GROWTH up to 1."""
        s = self.scale
        if s >= 1.0 or entries <= self.reference_entries:
            return s
        if not self.reference_entries > 0:          # learnt on programs without PSD blocks: no optimism beyond
            return 1.0
        return min(1.0, s * (entries / self.reference_entries) ** self.GROWTH)

    @staticmethod
    def _entries(psd_sides) -> float:
        return float(sum((s * (s + 1) // 2) ** 2 for s in psd_sides))

    def first_iteration(self, psd_sides, n_rows: int) -> float:
        """Predicted seconds of set-up + initial point + one iteration."""
        e = self._entries(psd_sides)
        return self.scale_for(e) * (self.FIXED + self.PER_ENTRY_FIRST * e + self.PER_ROW * n_rows)

    def reference_iteration(self, psd_sides, n_rows: int) -> float:
        """Seconds of one iteration at scale 1 (not what this machine measured: a function of the program only)."""
        return self.FIXED + self.PER_ENTRY_ITER * self._entries(psd_sides) + self.PER_ROW * n_rows

    def iteration(self, psd_sides, n_rows: int) -> float:
        """Predicted seconds of one interior-point iteration."""
        e = self._entries(psd_sides)
        return self.scale_for(e) * (self.FIXED + self.PER_ENTRY_ITER * e + self.PER_ROW * n_rows)

    def observe(self, psd_sides, n_rows: int, setup_seconds: float, solve_seconds: float, iterations: int) -> None:
        """Follow a measured call: set-up plus two iterations' worth of the solve (the initial point and
        the first iteration) against the prediction at scale 1.

        The model decides whether an attempt may start, so it errs on the slow side: a slower measurement is
        followed at once, a faster one only by a quarter of the way, and never below ``SCALE_RANGE[0]``.
        Programs predicted under ``MIN_CALIBRATED`` seconds are not observed: the per-entry terms were
        calibrated on large programs, and a fast small one says nothing about the next large one (a test
        suite's small programs pulled the scale to 1/4, and an 8-view Theorem 1 start then overran its
        3 s limit by 5 s).  A measurement that lowers the scale records its size in ``reference_entries``
        (the smallest such; :meth:`scale_for`)."""
        per_iter = solve_seconds / (max(int(iterations), 0) + 1)
        measured = setup_seconds + 2.0 * per_iter
        e = self._entries(psd_sides)
        predicted = self.FIXED + self.PER_ENTRY_FIRST * e + self.PER_ROW * n_rows
        if measured < 0.05 or predicted < self.MIN_CALIBRATED:
            return
        lo, hi = self.SCALE_RANGE
        ratio = min(hi, max(lo, measured / predicted))
        mixed = ratio if ratio >= self.scale else 0.75 * self.scale + 0.25 * ratio
        self.scale = min(hi, max(lo, mixed))
        if ratio < 1.0 and e > 0:
            self.reference_entries = min(self.reference_entries, e)


#: the process's model of Clarabel's uninterruptible time (used by the Clarabel back-end).
CLARABEL_TIME_MODEL = ClarabelTimeModel()


class BudgetExceeded(ValueError):
    """A program does not fit its :class:`Budget`; ``size`` is the estimate, ``hint`` the way out."""

    def __init__(self, reason: str, size: ProgramSize | None = None, hint: str = ""):
        self.size = size
        self.hint = hint
        super().__init__(reason + (f"; {hint}" if hint else ""))
