"""Sparse multivariate polynomials with real coefficients over named variables.

A :class:`Polynomial` is a map from exponent tuples to float coefficients over an
ordered tuple of variable names (its *generators*).  Arithmetic between
polynomials with different generators works on the union of the generators
(left operand's order first), so ``x + y`` is well defined whatever the origin of
``x`` and ``y``.

Only exact zeros are dropped from the term dictionary; no coefficient is ever
rounded.  Coefficients must be finite real numbers: NaN or inf raise :class:`ValueError`,
strings and booleans :class:`TypeError`.  Exponents must be non-negative integers
(``int`` or a numpy integer): a float exponent (even ``2.0``), a boolean or a numpy float
raises :class:`TypeError` naming the exponent instead of being truncated.

Size guards (O(1) checks, so that no call runs for minutes or exhausts memory): a product whose
term pairs exceed :data:`MAX_TERM_PRODUCTS`, and a power whose estimated size (the multinomial count
``C(t + k - 1, k)`` of terms of ``p**k`` for ``t`` terms, exact for generic terms) would need more
raise :class:`ValueError` naming the limit; :func:`variables` refuses more generators than
:data:`MAX_VARIABLES` (exponent tuples are dense: ``n`` variables hold ``n**2`` entries).
"""
from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Mapping, Sequence

import numpy as np

__all__ = ["Polynomial", "variables", "det", "as_polynomial", "sum_in_order", "MAX_TERM_PRODUCTS",
           "MAX_VARIABLES"]

Exponent = tuple  # tuple[int, ...]
#: largest number of term pairs one polynomial product may form (about 10-20 s of pure-Python work).
MAX_TERM_PRODUCTS = 20_000_000
#: most variables :func:`variables` creates at once (dense exponents: n**2 tuple entries, 8 bytes each).
MAX_VARIABLES = 16_384


def _check_finite(value: float, what: str = "coefficient") -> float:
    if isinstance(value, (str, bytes, bool, np.bool_, complex, np.complexfloating)):
        raise TypeError(f"polynomial {what} must be a real number, got {type(value).__name__} {value!r}")
    try:
        value = float(value)
    except TypeError:
        raise TypeError(f"polynomial {what} must be a real number, got {type(value).__name__}") from None
    except OverflowError:              # an int beyond the float range (10**400)
        digits = int(abs(int(value)).bit_length() * 0.30103) + 1
        raise ValueError(f"polynomial {what} must be finite, got an integer of about {digits} digits "
                         f"(beyond the floating-point range)") from None
    if not math.isfinite(value):
        raise ValueError(f"polynomial {what} must be finite, got {value!r}")
    return value


def _import_sympy():
    """``import sympy`` (an optional dependency, used only by the sympy converters)."""
    try:
        import sympy
    except ImportError as exc:
        raise ImportError("the sympy converters need sympy, an optional dependency: "
                          "pip install 'sospoly-tritools[sympy]'") from exc
    return sympy


class Polynomial:
    """A sparse real polynomial ``sum_e c_e * prod_k v_k**e_k``.

    Parameters
    ----------
    gens:
        Variable names, e.g. ``("x", "y")``.
    terms:
        Mapping from exponent tuples (one non-negative int per generator) to finite real coefficients.
    """

    __slots__ = ("gens", "terms")

    def __init__(self, gens: Sequence[str] = (), terms: Mapping[Exponent, float] | None = None):
        gens = tuple(str(g) for g in gens)
        if len(set(gens)) != len(gens):
            raise ValueError(f"duplicate variable names in {gens}")
        self.gens: tuple[str, ...] = gens
        clean: dict[Exponent, float] = {}
        n = len(gens)
        for e, c in (terms or {}).items():
            e = _exponent(e)
            if len(e) != n:
                raise ValueError(f"exponent {e} does not match the {n} variables {gens}")
            if any(k < 0 for k in e):
                raise ValueError(f"negative exponent {e}")
            c = _check_finite(c)
            if c != 0.0:
                clean[e] = clean.get(e, 0.0) + c
        self.terms: dict[Exponent, float] = {e: c for e, c in clean.items() if c != 0.0}

    # ------------------------------------------------------------------ constructors
    @classmethod
    def _raw(cls, gens: tuple, terms: dict) -> Polynomial:
        """Internal constructor for already-clean data (int exponent tuples, finite non-zero floats)."""
        p = object.__new__(cls)
        p.gens = gens
        p.terms = terms
        return p

    @classmethod
    def _checked(cls, gens: tuple, terms: dict) -> Polynomial:
        """Internal: drop exact zeros and refuse overflow to inf/NaN."""
        out = {}
        for e, c in terms.items():
            if c != 0.0:
                if not math.isfinite(c):
                    raise ValueError(f"polynomial arithmetic overflowed (coefficient {c!r})")
                out[e] = c
        return cls._raw(gens, out)

    @classmethod
    def from_trusted_terms(cls, gens: Sequence[str], terms: dict) -> Polynomial:
        """A polynomial from data the caller guarantees clean -- distinct variable names, exponent tuples of
        non-negative ints of the right length, finite non-zero float coefficients -- without the per-term
        validation of the constructor (for generated constraint sets with thousands of terms)."""
        return cls._raw(tuple(gens), dict(terms))

    @classmethod
    def constant(cls, value: float, gens: Sequence[str] = ()) -> Polynomial:
        gens = tuple(gens)
        return cls(gens, {(0,) * len(gens): value})

    @classmethod
    def from_sympy(cls, expr, gens: Sequence | None = None) -> Polynomial:
        """Convert a sympy expression (polynomial in ``gens``) to a Polynomial."""
        sympy = _import_sympy()
        expr = sympy.sympify(expr)
        if gens is None:
            syms = sorted(expr.free_symbols, key=lambda s: s.name)
        else:
            syms = [sympy.Symbol(g) if isinstance(g, str) else g for g in gens]
        try:
            poly = sympy.Poly(sympy.expand(expr), *syms) if syms else None
        except sympy.PolynomialError as exc:  # pragma: no cover - message path
            raise TypeError(f"not a polynomial in {syms}: {expr}") from exc
        names = tuple(s.name for s in syms)
        if poly is None:
            return cls.constant(float(expr), names)
        if poly.free_symbols_in_domain:
            raise TypeError(f"expression has symbols outside {names}: {expr}")
        return cls(names, {e: float(c) for e, c in poly.terms()})

    # ------------------------------------------------------------------ basic properties
    @property
    def nvars(self) -> int:
        return len(self.gens)

    @property
    def degree(self) -> int:
        """Total degree; -1 for the zero polynomial."""
        return max((sum(e) for e in self.terms), default=-1)

    def degree_in(self, name: str) -> int:
        k = self.gens.index(name)
        return max((e[k] for e in self.terms), default=-1)

    @property
    def is_zero(self) -> bool:
        return not self.terms

    def exponents(self) -> np.ndarray:
        """Exponent matrix, one row per term (order of ``terms``)."""
        return np.array(list(self.terms.keys()), dtype=np.int64).reshape(len(self.terms), self.nvars)

    def coefficients(self) -> np.ndarray:
        return np.array(list(self.terms.values()), dtype=float)

    def coefficient(self, exponent: Exponent) -> float:
        return self.terms.get(tuple(exponent), 0.0)

    def max_abs_coefficient(self) -> float:
        return max((abs(c) for c in self.terms.values()), default=0.0)

    # ------------------------------------------------------------------ generator alignment
    def with_gens(self, gens: Sequence[str]) -> Polynomial:
        """The same polynomial expressed over ``gens`` (must contain every used variable)."""
        gens = tuple(gens)
        if gens == self.gens:
            return self
        checked_gens(gens)
        pos = {g: i for i, g in enumerate(gens)}
        used = {self.gens[k] for e in self.terms for k, p in enumerate(e) if p}
        missing = used - set(gens)
        if missing:
            raise ValueError(f"variables {sorted(missing)} are not among {gens}")
        idx = [pos.get(g, -1) for g in self.gens]
        out: dict[Exponent, float] = {}
        n = len(gens)
        for e, c in self.terms.items():
            new = [0] * n
            for k, p in enumerate(e):
                if p:
                    new[idx[k]] = p
            out[tuple(new)] = c
        return Polynomial(gens, out)

    def _aligned(self, other: Polynomial) -> tuple[Polynomial, Polynomial]:
        if self.gens == other.gens:
            return self, other
        gens = self.gens + tuple(g for g in other.gens if g not in self.gens)
        return self.with_gens(gens), other.with_gens(gens)

    # ------------------------------------------------------------------ arithmetic
    def __add__(self, other) -> Polynomial:
        if not _is_operand(other):
            return NotImplemented
        other = as_polynomial(other, self.gens)
        a, b = self._aligned(other)
        out = dict(a.terms)
        for e, c in b.terms.items():
            out[e] = out.get(e, 0.0) + c
        return Polynomial._checked(a.gens, out)           # (a sum past the float range: refused, review 38a L3)

    __radd__ = __add__

    def __neg__(self) -> Polynomial:
        return Polynomial._raw(self.gens, {e: -c for e, c in self.terms.items()})

    def __pos__(self) -> Polynomial:
        return self

    def __sub__(self, other) -> Polynomial:
        if not _is_operand(other):
            return NotImplemented
        return self + (-as_polynomial(other, self.gens))

    def __rsub__(self, other) -> Polynomial:
        if not _is_operand(other):
            return NotImplemented
        return as_polynomial(other, self.gens) - self

    def __mul__(self, other) -> Polynomial:
        if isinstance(other, numbers.Real) and not isinstance(other, bool):
            s = _check_finite(other, "scalar")
            return Polynomial._checked(self.gens, {e: c * s for e, c in self.terms.items()})
        if not _is_operand(other):
            return NotImplemented
        other = as_polynomial(other, self.gens)
        _check_product_size(len(self.terms) * len(other.terms))
        a, b = self._aligned(other)
        out: dict[Exponent, float] = {}
        for e1, c1 in a.terms.items():
            for e2, c2 in b.terms.items():
                e = tuple(p + q for p, q in zip(e1, e2))
                out[e] = out.get(e, 0.0) + c1 * c2
        return Polynomial._checked(a.gens, out)

    __rmul__ = __mul__

    def __truediv__(self, other) -> Polynomial:
        if isinstance(other, numbers.Real) and not isinstance(other, bool):
            if other == 0:
                raise ZeroDivisionError("division of a polynomial by zero")
            return self * (1.0 / float(other))
        return NotImplemented

    def __pow__(self, k: int) -> Polynomial:
        if isinstance(k, (bool, np.bool_)) or not isinstance(k, numbers.Integral) or k < 0:
            raise ValueError(f"only non-negative integer powers are supported, got {k!r}")
        k = int(k)
        if len(self.terms) == 1:           # a monomial: one term whatever k (the coefficient is checked)
            (e, c), = self.terms.items()
            return Polynomial._checked(self.gens, {tuple(p * k for p in e): _power(c, k)})
        half = _power_terms(len(self.terms), k // 2)
        _check_product_size(half * half, f"p**{k} with {len(self.terms)} terms")
        result = Polynomial.constant(1.0, self.gens)
        base = self
        while k:
            if k & 1:
                result = result * base
            k >>= 1
            if k:
                base = base * base
        return result

    def __eq__(self, other) -> bool:  # exact structural equality
        try:
            other = as_polynomial(other, self.gens)
        except TypeError:
            return NotImplemented
        a, b = self._aligned(other)
        return a.terms == b.terms

    def __hash__(self):
        return hash((self.gens, frozenset(self.terms.items())))

    def allclose(self, other, atol: float = 1e-9, rtol: float = 1e-9) -> bool:
        """Coefficient-wise closeness test."""
        a, b = self._aligned(as_polynomial(other, self.gens))
        keys = set(a.terms) | set(b.terms)
        return all(
            abs(a.terms.get(e, 0.0) - b.terms.get(e, 0.0))
            <= atol + rtol * max(abs(a.terms.get(e, 0.0)), abs(b.terms.get(e, 0.0)))
            for e in keys
        )

    # ------------------------------------------------------------------ calculus & substitution
    def diff(self, name: str) -> Polynomial:
        """Partial derivative with respect to the variable ``name``."""
        if name not in self.gens:
            return Polynomial(self.gens, {})
        k = self.gens.index(name)
        out = {}
        for e, c in self.terms.items():
            if e[k]:
                e2 = list(e)
                e2[k] -= 1
                out[tuple(e2)] = c * e[k]
        return Polynomial(self.gens, out)

    def gradient(self) -> list[Polynomial]:
        return [self.diff(g) for g in self.gens]

    def subs(self, values: Mapping[str, object]) -> Polynomial:
        """Substitute numbers or polynomials for variables; keeps the other variables."""
        values = {str(k) if not isinstance(k, Polynomial) else _name_of(k): v for k, v in values.items()}
        unknown = set(values) - set(self.gens)
        if unknown:
            raise ValueError(f"cannot substitute unknown variables {sorted(unknown)}")
        keep = tuple(g for g in self.gens if g not in values)
        result = Polynomial(keep, {})
        repl = {g: as_polynomial(v, keep) for g, v in values.items()}
        power_cache: dict[tuple[str, int], Polynomial] = {}
        for e, c in self.terms.items():
            term = Polynomial(keep, {tuple(e[i] for i, g in enumerate(self.gens) if g not in values): c})
            for i, g in enumerate(self.gens):
                if g in values and e[i]:
                    key = (g, e[i])
                    if key not in power_cache:
                        power_cache[key] = repl[g] ** e[i]
                    term = term * power_cache[key]
            result = result + term
        return result

    def __call__(self, point) -> float | np.ndarray:
        return self.evaluate(point)

    def evaluate(self, points) -> float | np.ndarray:
        """Evaluate at one point (shape ``(n,)``) or many (shape ``(m, n)``), in ``gens`` order."""
        pts = np.asarray(points, dtype=float)
        single = pts.ndim == 1
        pts = np.atleast_2d(pts)
        if pts.shape[1] != self.nvars:
            raise ValueError(f"expected points with {self.nvars} coordinates {self.gens}, got shape {np.shape(points)}")
        if not self.terms:
            out = np.zeros(pts.shape[0])
        else:
            E = self.exponents()
            c = self.coefficients()
            out = np.ones((pts.shape[0], E.shape[0]))
            for k in range(self.nvars):
                col = E[:, k]
                if col.any():
                    out *= pts[:, [k]] ** col[None, :]
            out = out @ c
        return float(out[0]) if single else out

    # ------------------------------------------------------------------ conversion
    def to_sympy(self):
        """This polynomial as a sympy expression (needs the optional sympy)."""
        sympy = _import_sympy()
        syms = sympy.symbols(self.gens) if self.gens else ()
        if self.nvars == 1:
            syms = (syms,) if not isinstance(syms, tuple) else syms
        expr = sympy.Integer(0)
        for e, c in self.terms.items():
            term = sympy.Float(c)
            for s, p in zip(syms, e):
                if p:
                    term = term * s**p
            expr = expr + term
        return expr

    def __repr__(self) -> str:
        if not self.terms:
            return "Polynomial(0)"
        parts = []
        for e, c in sorted(self.terms.items(), key=lambda t: (-sum(t[0]), tuple(-k for k in t[0]))):
            mono = "*".join(f"{g}^{p}" if p > 1 else g for g, p in zip(self.gens, e) if p)
            parts.append(f"{c:+.6g}" + (f"*{mono}" if mono else ""))
        return "Polynomial(" + " ".join(parts) + ")"


def _power(c: float, k: int) -> float:
    try:
        return c ** k
    except OverflowError:
        return math.inf                  # refused by Polynomial._checked


def _power_terms(t: int, k: int) -> float:
    """Estimated number of terms of ``p**k`` for ``t`` terms: ``C(t + k - 1, k)`` (the monomials of
    degree k in t symbols; exact when the terms' exponents are generic), as a float (log-gamma)."""
    if t <= 1 or k <= 0:
        return 1.0
    log = math.lgamma(t + k) - math.lgamma(k + 1) - math.lgamma(t)
    return math.exp(min(log, 700.0))


def _check_product_size(pairs: float, what: str = "the product") -> None:
    if pairs > MAX_TERM_PRODUCTS:
        raise ValueError(f"{what} would form about {pairs:.3g} term pairs, more than the limit "
                         f"sospoly.algebra.polynomial.MAX_TERM_PRODUCTS = {MAX_TERM_PRODUCTS:.3g}")


def _exponent(e) -> tuple:
    """An exponent tuple of Python ints; TypeError naming it when it is not a sequence of integers (a float
    such as 1.5 used to be truncated by int() and the monomial silently changed)."""
    if isinstance(e, (str, bytes)) or not hasattr(e, "__iter__"):
        raise TypeError(f"exponent {e!r} must be a tuple of non-negative integers, got {type(e).__name__}")
    out = []
    for k in e:
        if type(k) is not int:
            if isinstance(k, (bool, np.bool_)) or not isinstance(k, numbers.Integral):
                raise TypeError(f"exponent {tuple(e)!r} must contain integers, got {k!r} ({type(k).__name__})")
            k = int(k)
        out.append(k)
    return tuple(out)


def _is_operand(value) -> bool:
    return isinstance(value, (Polynomial, numbers.Real, np.floating, np.integer)) and not isinstance(value, bool)


def _name_of(p: Polynomial) -> str:
    if len(p.terms) == 1:
        (e, c), = p.terms.items()
        if c == 1.0 and sum(e) == 1:
            return p.gens[e.index(1)]
    raise ValueError(f"{p} is not a single variable")


def as_polynomial(value, gens: Sequence[str] = ()) -> Polynomial:
    """Coerce a number or Polynomial to a Polynomial (numbers become constants over ``gens``)."""
    if isinstance(value, Polynomial):
        return value
    if isinstance(value, (numbers.Real, np.floating, np.integer)) and not isinstance(value, bool):
        return Polynomial.constant(_check_finite(value), gens)
    raise TypeError(f"expected a Polynomial or a real number, got {type(value).__name__}")


def variables(names: str | Iterable[str], n: int | None = None) -> tuple[Polynomial, ...]:
    """Create polynomial variables sharing one generator tuple.

    ``variables("x y z")`` returns three polynomials; ``variables("v", n=4)`` returns
    ``v1 .. v4``.
    """
    if n is not None:
        if not isinstance(names, str):
            raise TypeError("with n=..., names must be one prefix string")
        if isinstance(n, (bool, np.bool_)) or not isinstance(n, numbers.Integral) or n < 1:
            raise ValueError(f"n must be a positive integer, got {n!r}")
        if n > MAX_VARIABLES:           # before building n names (n = 10**9 took minutes, review 39b A9)
            raise ValueError(f"n = {n} variables exceed the limit sospoly.algebra.polynomial.MAX_VARIABLES = "
                             f"{MAX_VARIABLES} (exponents are dense: n variables hold n**2 entries)")
        gens = tuple(f"{names}{k}" for k in range(1, int(n) + 1))
    else:
        gens = tuple(names.replace(",", " ").split()) if isinstance(names, str) else tuple(names)
    if not gens:
        raise ValueError("no variable names given")
    m = len(gens)
    if m > MAX_VARIABLES:
        raise ValueError(f"{m} variables exceed the limit sospoly.algebra.polynomial.MAX_VARIABLES = "
                         f"{MAX_VARIABLES} (exponents are dense: n variables hold n**2 entries)")
    gens = tuple(str(g) for g in gens)
    bad = [g for g in gens if not g.isidentifier()]
    if bad:
        raise ValueError(f"variable names must be identifiers (a letter or _ first, then letters, digits, _), got "
                         f"{bad[:5]!r}")
    if len(set(gens)) != m:
        raise ValueError(f"duplicate variable names in {gens[:20]}")
    zero = (0,) * m                      # each exponent built by tuple slicing (C speed, no per-entry checks)
    return tuple(Polynomial._raw(gens, {zero[:k] + (1,) + zero[k + 1:]: 1.0}) for k in range(m))


def det(matrix: Sequence[Sequence[object]]) -> Polynomial:
    """Determinant of a small square matrix of polynomials (Laplace expansion, exact)."""
    rows = [list(r) for r in matrix]
    n = len(rows)
    if n == 0 or any(len(r) != n for r in rows):
        raise ValueError("det needs a non-empty square matrix")
    gens: tuple[str, ...] = ()
    for r in rows:
        for e in r:
            if isinstance(e, Polynomial):
                gens = gens + tuple(g for g in e.gens if g not in gens)
    M = [[as_polynomial(e, gens).with_gens(gens) if isinstance(e, Polynomial) else as_polynomial(e, gens)
          for e in r] for r in rows]

    def rec(cols: tuple[int, ...], row: int) -> Polynomial:
        if len(cols) == 1:
            return M[row][cols[0]]
        total = Polynomial(gens, {})
        for k, col in enumerate(cols):
            entry = M[row][col]
            if entry.is_zero:
                continue
            minor = rec(cols[:k] + cols[k + 1:], row + 1)
            total = total + entry * minor if k % 2 == 0 else total - entry * minor
        return total

    return rec(tuple(range(n)), 0)


def sum_in_order(gens: tuple, polys: list) -> Polynomial:
    """``Polynomial(gens, {}) + polys[0] + polys[1] + ...`` (left to right) in one dict: each addition adds its
    terms in order and a sum that reaches exactly 0 leaves (``Polynomial.__add__``'s terms, values and order), without
    copying and rehashing the partial sum at every step (O(N^2) over N views).  Polynomials over other generators
    are added by the arithmetic."""
    out: dict = {}
    total = None
    for p in polys:
        if total is not None or p.gens != gens:
            total = (Polynomial.from_trusted_terms(gens, out) if total is None else total) + p
            continue
        for e, c in p.terms.items():
            s = out.get(e, 0.0) + c
            if s != 0.0:
                out[e] = s
            else:
                out.pop(e, None)
    return Polynomial.from_trusted_terms(gens, out) if total is None else total


def checked_gens(gens) -> tuple:
    """``gens`` as a tuple of distinct variable names (TypeError naming an entry that is not a string, ValueError
    naming a repeated one)."""
    if isinstance(gens, (str, bytes)) or not hasattr(gens, "__iter__"):
        raise TypeError(f"gens must be a sequence of variable names (strings), got {type(gens).__name__}")
    gens = tuple(gens)
    for k, g in enumerate(gens):
        if not isinstance(g, str):
            raise TypeError(f"gens[{k}] must be a variable name (a string), got {g!r} ({type(g).__name__})")
    if len(set(gens)) < len(gens):
        seen = [g for k, g in enumerate(gens) if g in gens[:k]]
        raise ValueError(f"gens names variable {seen[0]!r} twice")
    return gens
