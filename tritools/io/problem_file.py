"""The JSON problem-file schema of ``tritools solve``: parse, validate, serialise.

A file holds one problem, a list of problems, or ``{"problems": [...]}``.  A problem
is one instance of the paper's eq. (5): N cameras ``P_i`` (3x4, world -> image) and N
admissible image regions ``R_i`` (SPEC §2)::

    {"name": "optional label",
     "cameras": [P_1, ..., P_N],            # each [[4 numbers], [4 numbers], [4 numbers]]
     "regions": [R_1, ..., R_N],            # Region.to_dict() forms, or [u, v] for a point
     "method": "theorem1" | "corollary1",   # optional per-problem overrides
     "delta": even int >= 2, "max_delta": int >= delta, "path": "sdp" | "auto",
     "comment": "ignored"}

Regions are exactly :meth:`tritools.model.regions.Region.to_dict` (extra keys ignored):
``{"type": "point", "x": [u, v]}``, ``{"type": "segment", "center": [..], "direction": [..]}``
(``{x^ + t d^ : |t| <= 1}``), ``{"type": "polytope", "B": [[b11, b12], ...], "c": [...]}``
(``{y : ||B y + c||_inf <= 1}``), ``{"type": "ellipse_border" | "ellipse", "center": [..],
"D": [[..], [..]]}`` (``(y - x^)' D^-1 (y - x^) = 1`` resp. ``<= 1``, D positive definite).

Every problem found is reported with a JSON-path-like location
(``problems[1].regions[0].D: must be positive definite ...``) through
:class:`ProblemFileError`.  NaN and +-Infinity, which Python's JSON parser accepts, are
rejected.  Only the file's structure is checked here; whether the triangulation is
well posed (e.g. all cameras equal, rank-deficient cameras) is reported by the solver as
a result status.  Nothing in this module prints.
"""
from __future__ import annotations

import enum
import json
import math
import re
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from ..model.constraints import Method
from ..model.regions import Point, Region
from ..result import TriangulationResult, jsonable
from ..solve.options import SolvePath

__all__ = ["ProblemFileError", "ProblemSpec", "PROBLEM_FIELDS", "region_types", "parse_problems",
           "parse_problem_text", "load_problem_file", "problem_to_dict", "problems_to_json",
           "result_to_dict", "result_from_dict", "jsonable"]

#: Keys allowed in a problem object (anything else is reported as an unknown field, to catch typos).
PROBLEM_FIELDS = ("name", "cameras", "regions", "method", "delta", "max_delta", "path", "comment")
#: Smallest number of views a triangulation problem can have.
MIN_VIEWS = 2


class ProblemFileError(ValueError):
    """A problem file is unreadable or does not follow the schema.

    ``location`` is a JSON-path-like address (``problems[1].regions[0].D``) or the file
    name; ``str(err)`` is the one-line message ``"location: problem"``.
    """

    def __init__(self, location: str, problem: str):
        self.location = location
        self.problem = problem
        super().__init__(f"{location}: {problem}" if location else problem)


@dataclass(frozen=True)
class ProblemSpec:
    """One validated problem: cameras (N, 3, 4), N regions and optional solver overrides."""

    cameras: np.ndarray
    regions: tuple
    name: str | None = None
    method: Method | None = None
    delta: int | None = None
    max_delta: int | None = None
    path: SolvePath | None = None

    @property
    def n_views(self) -> int:
        return len(self.regions)


# ----------------------------------------------------------------------------- helpers
def _join(loc: str, key) -> str:
    if isinstance(key, int):
        return f"{loc}[{key}]"
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
    """What the JSON decoder returns for ``NaN``/``Infinity`` literals, so that the
    validator can name the field holding them."""

    def __init__(self, literal: str):
        self.literal = literal


def _find_non_finite(value, loc: str) -> None:
    if isinstance(value, _NonFinite):
        raise ProblemFileError(loc or "$", f"non-finite number {value.literal} (NaN and Infinity are not allowed)")
    if isinstance(value, float) and not math.isfinite(value):
        raise ProblemFileError(loc or "$", f"non-finite number {value!r} (NaN and Infinity are not allowed)")
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > sys.float_info.max:
        raise ProblemFileError(loc or "$", f"integer with {len(str(abs(value)))} digits is too large for a "
                                           f"float (NaN and Infinity are not allowed)")
    if isinstance(value, Mapping):
        for k, v in value.items():
            _find_non_finite(v, _join(loc, k))
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _find_non_finite(v, _join(loc, i))


def _nested_shape(value, loc: str) -> tuple:
    """Shape of a nested list of numbers (ValueError naming the element otherwise)."""
    if isinstance(value, (list, tuple)):
        shapes = [_nested_shape(v, _join(loc, i)) for i, v in enumerate(value)]
        if any(s != shapes[0] for s in shapes[1:]):
            raise ProblemFileError(loc, f"ragged array: entries have shapes {sorted(set(shapes))}")
        return (len(value),) + (shapes[0] if shapes else ())
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ProblemFileError(loc, f"expected a number, got {_json_type(value)} {value!r}")
    return ()


def _numeric(value, loc: str, shape: tuple) -> np.ndarray:
    got = _nested_shape(value, loc)
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


_MISSING = re.compile(r"missing the field '(\w+)'")


def _parse_region(value, loc: str) -> Region:
    if isinstance(value, (list, tuple)):          # shorthand: [u, v] is a point region
        return Point(_numeric(value, loc, (2,)))
    if not isinstance(value, Mapping):
        raise ProblemFileError(loc, f"expected a region object or an [u, v] point, got {_json_type(value)}")
    if "type" not in value:
        raise ProblemFileError(_join(loc, "type"), "missing required field")
    kinds = region_types()
    if value["type"] not in kinds:
        raise ProblemFileError(_join(loc, "type"),
                               f"unknown region type {value['type']!r} (expected {', '.join(kinds)})")
    try:
        return Region.from_dict(value)
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        m = _MISSING.search(msg)
        if m:
            raise ProblemFileError(_join(loc, m.group(1)),
                                   f"missing required field of a {value['type']!r} region") from None
        head, _, rest = msg.partition(" ")
        if head in value and head != "type":        # region messages start with the field's name
            raise ProblemFileError(_join(loc, head), rest) from None
        raise ProblemFileError(loc, msg) from None


def _parse_int(value, loc: str, minimum: int, even: bool = False) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value):
        raise ProblemFileError(loc, f"expected an integer, got {_json_type(value)} {value!r}")
    v = int(value)
    if v < minimum or (even and v % 2):
        raise ProblemFileError(loc, f"expected an {'even ' if even else ''}integer >= {minimum}, got {v}")
    return v


def _parse_enum(enum_cls: type[enum.Enum], value, loc: str):
    try:
        return enum_cls(value)
    except ValueError:
        allowed = ", ".join(repr(e.value) for e in enum_cls)
        raise ProblemFileError(loc, f"expected one of {allowed}, got {value!r}") from None


def _parse_problem(obj, loc: str) -> ProblemSpec:
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
    regions = tuple(_parse_region(r, _join(rloc, i)) for i, r in enumerate(regs))
    name = obj.get("name")
    if name is not None and not isinstance(name, str):
        raise ProblemFileError(_join(loc, "name"), f"expected a string, got {_json_type(name)}")
    method = _parse_enum(Method, obj["method"], _join(loc, "method")) if "method" in obj else None
    delta = _parse_int(obj["delta"], _join(loc, "delta"), 2, even=True) if obj.get("delta") is not None else None
    max_delta = None
    if obj.get("max_delta") is not None:
        max_delta = _parse_int(obj["max_delta"], _join(loc, "max_delta"), delta or 2)
    path = _parse_enum(SolvePath, obj["path"], _join(loc, "path")) if "path" in obj else None
    return ProblemSpec(cameras, regions, name, method, delta, max_delta, path)


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
            raise ProblemFileError(str(extra[0]), "unknown top-level field next to 'problems' (allowed: comment)")
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
    return [_parse_problem(p, _join(prefix, i)) for i, p in enumerate(items)]


def parse_problem_text(text: str, source: str = "<input>") -> list[ProblemSpec]:
    """Decode JSON text (NaN/Infinity literals rejected with their location) and validate it."""
    try:
        data = json.loads(text, parse_constant=_NonFinite)
    except json.JSONDecodeError as exc:
        raise ProblemFileError(source, f"not valid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    except RecursionError:
        raise ProblemFileError(source, "not valid JSON: nested too deeply") from None
    return parse_problems(data)


def load_problem_file(path: str | Path) -> list[ProblemSpec]:
    """Read and validate a problem file (UTF-8 JSON)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ProblemFileError(str(path), f"cannot read: {reason}") from None
    return parse_problem_text(text, str(path))


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
