"""The JSON problem-file schema of ``tritools solve``: parse, validate, serialise.

A file holds one problem, a list of problems, or ``{"problems": [...]}``.  A problem
is one instance of the paper's eq. (5): N cameras ``P_i`` (3x4, world -> image) and N
admissible image regions ``R_i`` (SPEC §2)::

    {"name": "optional label",
     "cameras": [P_1, ..., P_N],            # each [[4 numbers], [4 numbers], [4 numbers]]
     "regions": [R_1, ..., R_N],            # Region.to_dict() forms, or [u, v] for a point
     "method": "auto" | "theorem1" | "corollary1",   # optional per-problem overrides
     "delta": even int >= 2, "max_delta": even int >= delta, "path": "auto" | "sdp",
     "comment": "ignored"}

Regions are exactly :meth:`tritools.model.regions.Region.to_dict` (extra keys ignored):
``{"type": "point", "x": [u, v]}``, ``{"type": "segment", "center": [..], "direction": [..]}``
(``{x^ + t d^ : |t| <= 1}``), ``{"type": "polytope", "B": [[b11, b12], ...], "c": [...]}``
(``{y : ||B y + c||_inf <= 1}``), ``{"type": "ellipse_border" | "ellipse", "center": [..],
"D": [[..], [..]]}`` (``(y - x^)' D^-1 (y - x^) = 1`` resp. ``<= 1``, D positive definite).

Every problem found is reported with a JSON-path-like location
(``problems[1].regions[0].D: must be positive definite ...``) through
:class:`ProblemFileError`.  NaN and +-Infinity, which Python's JSON parser accepts, are
rejected, and so are integer literals too large for a float (whatever their number of
digits).  The solver settings (method, delta, max_delta, path) are validated by
:class:`tritools.solve.options.TriangulationOptions` -- the same rules as the command-line
flags -- and reported at their location.  Only the file's structure is checked here; whether
the triangulation is well posed (e.g. all cameras equal, rank-deficient cameras) is reported by the solver as
a result status.  Nothing in this module prints.
"""
from __future__ import annotations

import json
import math
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from collections.abc import Iterable

import numpy as np

from ..errors import MISSING, FieldError
from ..model.regions import Point, Region
from ..result import TriangulationResult, jsonable
from ..solve.options import MethodChoice, OptionError, SolvePath, TriangulationOptions

__all__ = ["ProblemFileError", "ProblemSpec", "PROBLEM_FIELDS", "region_types", "parse_problems",
           "parse_problem_text", "parse_problem_bytes", "load_problem_file", "problem_to_dict", "problems_to_json",
           "result_to_dict", "result_from_dict", "jsonable"]

#: Keys allowed in a problem object (anything else is reported as an unknown field, to catch typos).
PROBLEM_FIELDS = ("name", "cameras", "regions", "method", "delta", "max_delta", "path", "comment")
#: The solver settings a problem may override, validated by :class:`TriangulationOptions`.
OPTION_FIELDS = ("method", "delta", "max_delta", "path")
#: Smallest number of views a triangulation problem can have.
MIN_VIEWS = 2
#: An integer literal with more digits than this is beyond the float range (10**309 > 1.8e308).
MAX_FLOAT_DIGITS = 309


class ProblemFileError(ValueError):
    """A problem file is unreadable or does not follow the schema.

    ``location`` is a JSON-path-like address (``problems[1].regions[0].D``) or the file
    name; ``str(err)`` is the one-line message ``"location: problem"``.
    """

    def __init__(self, location: str, problem: str):
        self.location = _one_line(location, 200)
        self.problem = _one_line(problem, 300)
        super().__init__(f"{self.location}: {self.problem}" if self.location else self.problem)


def _one_line(text: str, limit: int) -> str:
    """``text`` on one line (control characters escaped) and at most ``limit`` characters (a message must never
    print a whole document)."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(text))
    return text if len(text) <= limit else text[:limit] + "..."


@dataclass(frozen=True)
class ProblemSpec:
    """One validated problem: cameras (N, 3, 4), N regions and optional solver overrides
    (``None``: not given; ``method`` is a :class:`MethodChoice`, ``auto`` included)."""

    cameras: np.ndarray
    regions: tuple
    name: str | None = None
    method: MethodChoice | None = None
    delta: int | None = None
    max_delta: int | None = None
    path: SolvePath | None = None

    @property
    def n_views(self) -> int:
        return len(self.regions)


# ----------------------------------------------------------------------------- helpers
_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def _join(loc: str, key) -> str:
    if isinstance(key, int):
        return f"{loc}[{key}]"
    if not _IDENTIFIER.fullmatch(str(key)):          # a key such as "a b" or "\n": quoted, JSON-escaped
        return f"{loc}[{json.dumps(str(key))}]"
    return f"{loc}.{key}" if loc else str(key)


def _json_type(v) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "boolean"
    if isinstance(v, (int, float)):
        return "number"
    if isinstance(v, str):
        return "string"
    if isinstance(v, (list, tuple)):
        return "array"
    if isinstance(v, Mapping):
        return "object"
    return type(v).__name__


class _NonFinite:
    """What the JSON decoder returns for ``NaN``/``Infinity`` literals and for integer literals too
    long for a float, so that the validator can name the field holding them."""

    def __init__(self, literal: str, problem: str | None = None):
        self.literal = literal
        self.problem = problem or f"non-finite number {literal} (NaN and Infinity are not allowed)"


def _json_int(literal: str):
    """``parse_int`` of the decoder: Python's int() refuses literals of more than 4300 digits (a ValueError
    that named no field); any literal beyond the float range is reported where it stands instead."""
    digits = len(literal.lstrip("-"))
    if digits > MAX_FLOAT_DIGITS:
        return _NonFinite(literal[:12] + "...", f"integer with {digits} digits is too large for a float "
                                                f"(NaN and Infinity are not allowed)")
    return int(literal)


def _plainly_finite(data) -> bool:
    """True when decoded JSON holds only plain finite numbers, strings, booleans and nulls in lists and dicts
    (one pass without locations: the common case of :func:`_find_non_finite`); False when anything else is
    seen, which the located walk then examines."""
    stack, finite, big = [data], math.isfinite, sys.float_info.max
    while stack:
        value = stack.pop()
        kind = type(value)
        if kind is list:
            stack.extend(value)
        elif kind is dict:
            stack.extend(value.values())
        elif kind is float:
            if not finite(value):
                return False
        elif kind is int:
            if abs(value) > big:
                return False
        elif not (kind is str or kind is bool or value is None):
            return False
    return True


def _find_non_finite(data, root: str) -> None:
    """The first non-finite number of decoded JSON, by location (iterative: no recursion limit)."""
    if _plainly_finite(data):
        return
    stack = [(data, root)]
    while stack:
        value, loc = stack.pop()
        if isinstance(value, _NonFinite):
            raise ProblemFileError(loc or "$", value.problem)
        if isinstance(value, float) and not math.isfinite(value):
            raise ProblemFileError(loc or "$", f"non-finite number {value!r} (NaN and Infinity are not allowed)")
        if isinstance(value, int) and not isinstance(value, bool) and abs(value) > sys.float_info.max:
            raise ProblemFileError(loc or "$", f"integer with {len(str(abs(value)))} digits is too large for a "
                                               f"float (NaN and Infinity are not allowed)")
        if isinstance(value, Mapping):
            stack.extend(reversed([(v, _join(loc, k)) for k, v in value.items()]))
        elif isinstance(value, (list, tuple)):
            stack.extend(reversed([(v, _join(loc, i)) for i, v in enumerate(value)]))


def _nested_shape(value, loc: str, depth: int) -> tuple:
    """Shape of a nested list of numbers at most ``depth`` deep (ProblemFileError naming the element otherwise)."""
    if isinstance(value, (list, tuple)):
        if depth <= 0:
            raise ProblemFileError(loc, "expected a number, got array")
        shapes = [_nested_shape(v, _join(loc, i), depth - 1) for i, v in enumerate(value)]
        if any(s != shapes[0] for s in shapes[1:]):
            raise ProblemFileError(loc, f"ragged array: entries have shapes {sorted(set(shapes))}")
        return (len(value),) + (shapes[0] if shapes else ())
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProblemFileError(loc, f"expected a number, got {_json_type(value)} {_short(value)}")
    return ()


def _short(value, limit: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[:limit] + "..."


def _plain_shape(value, shape: tuple) -> bool:
    """True when ``value`` is nested lists of exactly ``shape`` holding plain ints and floats (the common case of
    :func:`_numeric`, checked without building locations)."""
    rows = [value]
    for n in shape:
        if not all(type(r) is list and len(r) == n for r in rows):
            return False
        rows = [v for r in rows for v in r]
    return all(type(v) is float or type(v) is int for v in rows)


def _numeric(value, loc: str, shape: tuple) -> np.ndarray:
    if _plain_shape(value, shape):
        return np.array(value, dtype=float)
    got = _nested_shape(value, loc, len(shape))
    if got != shape:
        raise ProblemFileError(loc, f"expected shape {shape}, got {got}")
    return np.array(value, dtype=float)


def region_types() -> tuple[str, ...]:
    """``kind`` of every concrete :class:`Region` subclass, in definition order."""
    out, stack = [], list(reversed(Region.__subclasses__()))
    while stack:
        cls = stack.pop()
        if cls.kind and cls.kind not in out:
            out.append(cls.kind)
        stack.extend(reversed(cls.__subclasses__()))
    return tuple(out)


def _parse_region(value, loc: str, kinds: tuple | None = None) -> Region:
    if isinstance(value, (list, tuple)):          # shorthand: [u, v] is a point region
        return Point(_numeric(value, loc, (2,)))
    if not isinstance(value, Mapping):
        raise ProblemFileError(loc, f"expected a region object or an [u, v] point, got {_json_type(value)}")
    if "type" not in value:
        raise ProblemFileError(_join(loc, "type"), "missing required field")
    kinds = region_types() if kinds is None else kinds
    if value["type"] not in kinds:
        raise ProblemFileError(_join(loc, "type"),
                               f"unknown region type {_short(value['type'])} (expected {', '.join(kinds)})")
    try:
        return Region.from_dict(value)
    except FieldError as exc:                       # the region names its field: its location in the file
        if exc.reason == MISSING:
            raise ProblemFileError(_join(loc, exc.field),
                                   f"missing required field of a {_short(value['type'])} region") from None
        if exc.field in value and exc.field != "type":
            raise ProblemFileError(_join(loc, exc.field), exc.text) from None
        raise ProblemFileError(loc, str(exc)) from None
    except (ValueError, TypeError) as exc:
        raise ProblemFileError(loc, str(exc)) from None


def _shortened(text: str, given: Mapping) -> str:
    """``text`` with the long values of ``given`` (a 300-digit delta) shortened, for a one-line message."""
    for value in given.values():
        for long in {repr(value), str(value)} | ({str(int(value))} if isinstance(value, float) else set()):
            if len(long) > 60:
                text = text.replace(long, _short(value))
    return text


def _parse_options(obj: Mapping, loc: str) -> dict:
    """The solver settings of a problem (``null`` = not given), validated by :class:`TriangulationOptions` --
    the one validation of the command-line flags too -- with the message placed at the field's location."""
    given = {k: obj[k] for k in OPTION_FIELDS if obj.get(k) is not None}
    if not given:
        return {}
    for key, value in given.items():           # a JSON string or number only: a message never prints a document
        if isinstance(value, (list, tuple, Mapping)):
            raise ProblemFileError(_join(loc, key), f"expected a {'string' if key in ('method', 'path') else 'number'}"
                                                    f", got {_json_type(value)}")
    try:
        opts = TriangulationOptions(**given)
    except OptionError as exc:                # the field it names, and its text, at the field's location
        if exc.field not in given:            # not a message about one field: the problem object itself
            raise ProblemFileError(loc or "$", _shortened(str(exc), given)) from None
        raise ProblemFileError(_join(loc, exc.field), _shortened(exc.text, given)) from None
    return {k: getattr(opts, k) for k in given}


def _parse_problem(obj, loc: str, kinds: tuple | None = None) -> ProblemSpec:
    if not isinstance(obj, Mapping):
        raise ProblemFileError(loc or "$", f"expected a problem object, got {_json_type(obj)}")
    for key in obj:
        if key not in PROBLEM_FIELDS:
            raise ProblemFileError(_join(loc, key), f"unknown field (expected {', '.join(PROBLEM_FIELDS)})")
    for key in ("cameras", "regions"):
        if key not in obj:
            raise ProblemFileError(_join(loc, key), "missing required field")
    cams = obj["cameras"]
    cloc = _join(loc, "cameras")
    if not isinstance(cams, (list, tuple)):
        raise ProblemFileError(cloc, f"expected an array of 3x4 camera matrices, got {_json_type(cams)}")
    if len(cams) < MIN_VIEWS:
        raise ProblemFileError(cloc, f"at least {MIN_VIEWS} cameras are needed, got {len(cams)}")
    cameras = np.array([_numeric(P, _join(cloc, i), (3, 4)) for i, P in enumerate(cams)])
    regs = obj["regions"]
    rloc = _join(loc, "regions")
    if not isinstance(regs, (list, tuple)):
        raise ProblemFileError(rloc, f"expected an array of regions, got {_json_type(regs)}")
    if len(regs) != len(cams):
        raise ProblemFileError(rloc, f"expected one region per camera ({len(cams)}), got {len(regs)}")
    kinds = region_types() if kinds is None else kinds
    regions = tuple(_parse_region(r, _join(rloc, i), kinds) for i, r in enumerate(regs))
    name = obj.get("name")
    if name is not None and not isinstance(name, str):
        raise ProblemFileError(_join(loc, "name"), f"expected a string, got {_json_type(name)}")
    return ProblemSpec(cameras, regions, name, **_parse_options(obj, loc))


# ----------------------------------------------------------------------------- parsing
def parse_problems(data: Any) -> list[ProblemSpec]:
    """Validate decoded JSON (a problem, a list of problems or ``{"problems": [...]}``).

    Raises
    ------
    ProblemFileError
        At the first problem found, with its location.
    """
    _find_non_finite(data, "")
    if isinstance(data, Mapping) and "problems" in data:
        extra = [k for k in data if k not in ("problems", "comment")]
        if extra:
            raise ProblemFileError(_join("", extra[0]), "unknown top-level field next to 'problems' (allowed: comment)")
        items, prefix = data["problems"], "problems"
        if not isinstance(items, list):
            raise ProblemFileError(prefix, f"expected an array of problems, got {_json_type(items)}")
    elif isinstance(data, list):
        items, prefix = data, ""
    elif isinstance(data, Mapping):
        return [_parse_problem(data, "")]
    else:
        raise ProblemFileError("$", f"expected a problem object, an array of problems or "
                                    f"{{\"problems\": [...]}}, got {_json_type(data)}")
    if not items:
        raise ProblemFileError(prefix or "$", "no problems")
    kinds = region_types()
    return [_parse_problem(p, _join(prefix, i), kinds) for i, p in enumerate(items)]


def parse_problem_text(text: str, source: str = "<input>") -> list[ProblemSpec]:
    """Decode JSON text (NaN/Infinity literals rejected with their location) and validate it."""
    if not isinstance(text, str):
        raise TypeError(f"text must be a str, got {type(text).__name__}")
    if not text.strip():
        raise ProblemFileError(source, "empty file (expected a JSON problem, an array of problems or "
                                       "{\"problems\": [...]})")
    try:
        data = json.loads(text, parse_constant=_NonFinite, parse_int=_json_int, object_pairs_hook=_unique_keys)
    except _DuplicateKey as exc:
        raise ProblemFileError(f"{source}:{_duplicate_line(text, exc.key)}",
                               f"duplicated key {exc.key!r} (each field may appear once)") from None
    except json.JSONDecodeError as exc:
        raise ProblemFileError(source, f"not valid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    except RecursionError:
        raise ProblemFileError(source, "not valid JSON: nested too deeply") from None
    try:
        return parse_problems(data)
    except RecursionError:                     # a region or shape nested far deeper than any schema field
        raise ProblemFileError(source, "nested too deeply for the problem-file schema") from None


class _DuplicateKey(ValueError):
    def __init__(self, key: str):
        super().__init__(key)
        self.key, self.pos = key, None


def _unique_keys(pairs: list) -> dict:
    """``object_pairs_hook``: the object, or :class:`_DuplicateKey` when a key repeats (json would
    silently keep the last value: ``"delta": 3, "delta": 4``)."""
    obj = dict(pairs)
    if len(obj) != len(pairs):
        seen: set = set()
        raise _DuplicateKey(next(k for k, _ in pairs if k in seen or seen.add(k)))
    return obj


def _duplicate_line(text: str, key: str) -> int:
    """The line of the repeated ``key``: the text is decoded again by json's pure-Python scanner
    (error path only), which tells where the offending object starts; the key's second occurrence
    after that start is the duplicate."""
    def parse_object(s_and_end, *args):
        try:
            return json.decoder.JSONObject(s_and_end, *args)
        except _DuplicateKey as exc:
            exc.pos = s_and_end[1] if exc.pos is None else exc.pos      # the innermost object's start
            raise
    decoder = json.JSONDecoder(parse_constant=_NonFinite, parse_int=_json_int, object_pairs_hook=_unique_keys)
    decoder.parse_object = parse_object
    decoder.scan_once = json.scanner.py_make_scanner(decoder)
    start = 0
    try:
        decoder.decode(text)
    except _DuplicateKey as exc:
        start = exc.pos or 0
    except (ValueError, RecursionError):
        pass
    hits = [m.start() for m in re.finditer(re.escape(json.dumps(key)) + r"\s*:", text[start:])]
    at = start + (hits[1] if len(hits) > 1 else hits[0] if hits else 0)
    return text.count("\n", 0, at) + 1


def load_problem_file(path: str | Path) -> list[ProblemSpec]:
    """Read and validate a problem file (UTF-8 JSON)."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:               # missing, a directory, no permission, ...
        raise ProblemFileError(str(path), f"cannot read: {exc.strerror or exc}") from None
    return parse_problem_bytes(raw, str(path))


def parse_problem_bytes(raw: bytes, source: str = "<input>") -> list[ProblemSpec]:
    """:func:`parse_problem_text` of UTF-8 bytes (a byte-order mark is tolerated); bytes that are not UTF-8
    are a :class:`ProblemFileError` at ``source:line``."""
    try:
        text = bytes(raw).decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise ProblemFileError(f"{source}:{line}", f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset "
                                                   f"{exc.start})") from None
    return parse_problem_text(text, source)


# ----------------------------------------------------------------------------- serialising
def problem_to_dict(cameras, regions, name: str | None = None, **overrides) -> dict:
    """The schema's object for one problem (``overrides``: method, delta, max_delta, path)."""
    d: dict[str, Any] = {} if name is None else {"name": name}
    d["cameras"] = np.asarray(cameras, dtype=float).tolist()
    d["regions"] = [r.to_dict() if isinstance(r, Region) else Point(r).to_dict() for r in regions]
    for key, value in overrides.items():
        if key not in PROBLEM_FIELDS:
            raise ValueError(f"unknown problem field {key!r} (expected {', '.join(PROBLEM_FIELDS)})")
        if value is not None:
            d[key] = getattr(value, "value", value)
    return d


def problems_to_json(problems: Iterable[dict], indent: int | None = 1) -> str:
    """``{"problems": [...]}`` text for :func:`problem_to_dict` objects (validated first)."""
    doc = {"problems": list(problems)}
    parse_problems(doc)
    return json.dumps(doc, indent=indent, allow_nan=False)


def result_to_dict(result: TriangulationResult, **extra) -> dict:
    """``extra`` (e.g. name, index) then every field of ``result`` in its one JSON form
    (:meth:`TriangulationResult.to_dict`: NaN-free, attempts as objects)."""
    return {**{k: jsonable(v) for k, v in extra.items()}, **result.to_dict()}


def result_from_dict(d: Mapping) -> TriangulationResult:
    """Inverse of :func:`result_to_dict` (extra keys ignored; ``null`` stays ``None``)."""
    return TriangulationResult.from_dict(d)
