"""One result record: the results of M triangulation problems as columns (issue #18).

:class:`TriangulationResults` is what every batch entry point returns (``triangulate_many``,
``triangulate_points``, the SfM workflow through :mod:`tritools.sfm`): arrays whose first axis is the
problem, plus a :class:`~tritools.result.Status` column.  It is a ``Sequence`` of rows: ``results[i]`` is the
:class:`~tritools.result.TriangulationResult` of problem i (built on access), ``len``, iteration and slicing
work as on a list; ``results.gamma_ub`` is a whole column.  A new per-point field is one column here and one
field of the row.

Columns (M problems, W view slots):

========================  ==============  ========================================================
``method``                (M,) object     method name of each row
``status``                (M,) object     :class:`~tritools.result.Status` members
``X``, ``X_raw``          (M, 3) float    estimate (NaN row: the row's ``None``)
``gamma_lb``, ``gamma_ub``, ``gamma_ub_raw``  (M,) float  bounds ``gamma_lb <= gamma* <= gamma_ub`` (paper eqs. (6),
                                          (44)); NaN: the row's ``None``
``optimal``, ``in_front`` (M,) bool       ``False`` where the row says ``None`` (``null`` tells which)
``delta``, ``n_lmivar``   (M,) int        -1: the row's ``None``
``certified_by``, ``sparsity``  (M,) object  text or ``None``
``message``               (M,) object     text
``attempts``              (M,) object     tuples of :class:`~tritools.result.Attempt`
``timings``               name -> (M,) float  NaN where a row has no such timing
``n_views``               (M,) int        views of each problem
``image_points``          (M, W, 2) float per-view columns (ragged: row i has ``n_views[i]`` entries, in the
``depths``, ``residuals`` (M, W) float    first slots, or where ``views[i]`` is True); ``None`` when no row has
``inliers``               (M, W) bool     them
``views``                 (M, W) bool     optional: which slots hold row i's views (``triangulate_points``:
                                          its visibility mask); ``None``: the first ``n_views[i]``
``null``                  name -> (M,) bool  rows whose boolean or per-view value is ``None``
========================  ==============  ========================================================

The one JSON form (:meth:`TriangulationResults.to_dict`) is ``{"results": [row.to_dict(), ...],
"views": [[slot, ...], ...], "width": W}``: its i-th result *is* the i-th row's
:meth:`~tritools.result.TriangulationResult.to_dict` (NaN and infinity as ``null``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from .result import Attempt, Status, TriangulationResult

__all__ = ["TriangulationResults", "FLOAT_COLUMNS", "INT_COLUMNS", "BOOL_COLUMNS", "TEXT_COLUMNS",
           "POINT_COLUMNS", "VIEW_COLUMNS"]

#: scalar float columns (NaN: ``None`` in the row)
FLOAT_COLUMNS = ("gamma_lb", "gamma_ub", "gamma_ub_raw")
#: integer columns (-1: ``None`` in the row)
INT_COLUMNS = ("delta", "n_lmivar")
#: boolean columns (a ``None`` in the row: ``False`` here and True in ``null``)
BOOL_COLUMNS = ("optimal", "in_front")
#: text columns (object arrays of ``str`` or ``None``)
TEXT_COLUMNS = ("method", "certified_by", "sparsity")
#: 3-vector columns (a NaN row: ``None`` in the row)
POINT_COLUMNS = ("X", "X_raw")
#: per-view columns: name -> (trailing shape, dtype, fill)
VIEW_COLUMNS = {"image_points": ((2,), float, np.nan), "depths": ((), float, np.nan),
                "residuals": ((), float, np.nan), "inliers": ((), bool, False)}
_NULLABLE = BOOL_COLUMNS + tuple(VIEW_COLUMNS)
#: the value of each scalar column in a row that does not have it
_DEFAULTS = {**dict.fromkeys(POINT_COLUMNS + FLOAT_COLUMNS, np.nan), **dict.fromkeys(INT_COLUMNS, -1), "n_views": 0,
             **dict.fromkeys(BOOL_COLUMNS, False), "certified_by": None, "sparsity": None, "message": "",
             "attempts": ()}
_STATUS = {**{s: s for s in Status}, **{s.value: s for s in Status}}


def _bad(name: str, what: str) -> ValueError:
    return ValueError(f"TriangulationResults.{name} {what}")


def _frozen(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


def _absent(name: str, M: int) -> np.ndarray:
    """An absent column: its default broadcast over the M rows (read-only, no memory per row)."""
    value = _DEFAULTS[name]
    if value is None or isinstance(value, (str, tuple)):
        one = np.empty(1, object)
        one[0] = value
        return np.broadcast_to(one, (M,))
    dtype = float if name in POINT_COLUMNS + FLOAT_COLUMNS else bool if name in BOOL_COLUMNS else int
    return np.broadcast_to(np.array(value, dtype), (M, 3) if name in POINT_COLUMNS else (M,))


def _is_absent(name: str, arr) -> bool:
    """``arr`` is column ``name`` absent: its default broadcast (every stride 0), as :func:`_absent` builds it."""
    if not isinstance(arr, np.ndarray) or arr.size == 0 or any(arr.strides) or name not in _DEFAULTS:
        return False
    value, default = arr.flat[0], _DEFAULTS[name]
    if isinstance(default, float):
        return bool(np.isnan(value))
    if default is None:
        return value is None
    return bool(value == default)


def _objects(values, M: int, name: str) -> np.ndarray:
    """An (M,) object array of ``values`` (tuples stay elements, never a second axis)."""
    values = list(values)
    if len(values) != M:
        raise _bad(name, f"must have {M} entries, got {len(values)}")
    return _frozen(np.fromiter(values, dtype=object, count=M))


def _numbers(name: str, value, shape: tuple, dtype) -> np.ndarray:
    """A copy of ``value`` as ``dtype`` (float, int or bool) with ``shape``; text, objects, non-integral numbers
    for an integer column and numbers other than 0/1 for a boolean one are refused (ValueError naming the
    column)."""
    try:
        arr = np.array(value)
    except (TypeError, ValueError) as exc:
        raise _bad(name, f"must be a numeric array, got {type(value).__name__}") from exc
    if arr.shape != shape:
        raise _bad(name, f"must have shape {shape}, got {arr.shape}")
    kind = arr.dtype.kind
    if kind not in ("biuf" if dtype is bool else "iuf"):
        raise _bad(name, f"must be {'booleans' if dtype is bool else 'real numbers'}, got dtype {arr.dtype}")
    if dtype is bool and kind != "b" and not np.all((arr == 0) | (arr == 1)):
        raise _bad(name, f"must be booleans, got dtype {arr.dtype}")
    if dtype is int and kind == "f" and not np.all(np.isfinite(arr) & (arr == np.round(arr))):
        raise _bad(name, "must be integers")
    return _frozen(arr.astype(dtype))


def _statuses(values, M: int) -> np.ndarray:
    try:
        return _objects((_STATUS[v] for v in values), M, "status")
    except (KeyError, TypeError) as exc:
        raise _bad("status", f"must hold Status values ({', '.join(s.value for s in Status)}), got {exc}") from None


def _texts(name: str, values, M: int, optional: bool) -> np.ndarray:
    if values is None:
        return _absent(name, M) if name != "method" else _objects([""] * M, M, name)
    values = list(values)
    for v in values:
        if not (isinstance(v, str) or (optional and v is None)):
            raise _bad(name, f"must hold text{' or None' if optional else ''}, got {v!r}")
    return _objects((None if v is None else str(v) for v in values), M, name)


def _opt(value: float):
    return None if value != value else float(value)


@dataclass(frozen=True, eq=False)
class TriangulationResults(Sequence):
    """Results of M triangulation problems as columns; a ``Sequence`` of
    :class:`~tritools.result.TriangulationResult` rows (see the module docstring for every column).

    Only ``method`` and ``status`` are required; every other column defaults to "absent": its default (NaN, -1,
    ``False`` -- ``None`` in a row only where ``null`` says so --, ``None`` or empty text, no attempts) broadcast
    over the rows, which costs no memory per row and stays absent through :meth:`concat` and :meth:`take`.
    Construction copies and checks every column (shape, dtype, status values) and raises ValueError naming
    the column."""

    method: Any
    status: Any
    X: Any = None
    gamma_ub: Any = None
    gamma_lb: Any = None
    optimal: Any = None
    delta: Any = None
    n_lmivar: Any = None
    X_raw: Any = None
    gamma_ub_raw: Any = None
    certified_by: Any = None
    message: Any = None
    timings: Mapping = field(default_factory=dict)
    attempts: Any = None
    sparsity: Any = None
    in_front: Any = None
    n_views: Any = None
    image_points: Any = None
    depths: Any = None
    residuals: Any = None
    inliers: Any = None
    views: Any = None
    null: Mapping = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in _DEFAULTS:                  # an absent column given back (dataclasses.replace) stays absent
            if _is_absent(name, getattr(self, name)):
                set_(self, name, None)
        status = list(self.status) if not isinstance(self.status, (str, Status)) else None
        if status is None:
            raise _bad("status", f"must be a sequence of Status values, got {self.status!r}")
        M = len(status)
        set_(self, "status", _statuses(status, M))
        for name in TEXT_COLUMNS:
            set_(self, name, _texts(name, getattr(self, name), M, optional=name != "method"))
        set_(self, "message", _texts("message", self.message, M, optional=False))
        self._check_numbers(M)
        set_(self, "attempts", _absent("attempts", M) if self.attempts is None else
             _objects((tuple(Attempt.from_dict(a) if isinstance(a, dict) else a for a in t) for t in self.attempts),
                      M, "attempts"))
        set_(self, "timings", {str(k): _numbers(f"timings[{k!r}]", v, (M,), float) for k, v in self.timings.items()})
        self._check_views(M)
        set_(self, "null", {k: self._null_mask(k, v, M) for k, v in self.null.items() if np.any(v)})

    def _check_numbers(self, M: int) -> None:
        set_ = object.__setattr__
        for names, tail, dtype in ((POINT_COLUMNS, (3,), float), (FLOAT_COLUMNS, (), float),
                                   (INT_COLUMNS + ("n_views",), (), int), (BOOL_COLUMNS, (), bool)):
            for name in names:
                value = getattr(self, name)
                set_(self, name, _absent(name, M) if value is None else _numbers(name, value, (M,) + tail, dtype))
        if np.any(self.n_views < 0):
            raise _bad("n_views", "must be >= 0")

    def _check_views(self, M: int) -> None:
        present = [getattr(self, k) for k in VIEW_COLUMNS if getattr(self, k) is not None]
        widths = {np.shape(v)[1] for v in present if np.ndim(v) >= 2}
        if self.views is not None:
            widths.add(np.shape(self.views)[1] if np.ndim(self.views) == 2 else -1)
        W = max(widths | {int(self.n_views.max(initial=0))})
        set_ = object.__setattr__
        if self.views is not None:
            views = _numbers("views", self.views, (M, W), bool)
            if not np.array_equal(views.sum(axis=1), self.n_views):
                raise _bad("views", "must mark n_views slots of each row")
            set_(self, "views", views)
        for name, (tail, dtype, _) in VIEW_COLUMNS.items():
            if getattr(self, name) is not None:
                set_(self, name, _numbers(name, getattr(self, name), (M, W) + tail, dtype))

    def _null_mask(self, name: str, value, M: int) -> np.ndarray:
        if name not in _NULLABLE:
            raise _bad("null", f"names the boolean and per-view columns ({', '.join(_NULLABLE)}), got {name!r}")
        return _numbers(f"null[{name!r}]", value, (M,), bool)

    # ------------------------------------------------------------------ rows
    def __len__(self) -> int:
        return len(self.status)

    @property
    def width(self) -> int:
        """W, the number of view slots of the per-view columns."""
        if self.views is not None:
            return self.views.shape[1]
        present = [getattr(self, k) for k in VIEW_COLUMNS if getattr(self, k) is not None]
        return present[0].shape[1] if present else int(self.n_views.max(initial=0))

    def slots(self, i: int) -> np.ndarray:
        """The view slots of row i (indices into the second axis of the per-view columns)."""
        if self.views is not None:
            return np.nonzero(self.views[i])[0]
        return np.arange(self.n_views[i])

    def _is_null(self, name: str, i: int) -> bool:
        """Row i says ``None`` for the boolean or per-view column ``name``."""
        if name in VIEW_COLUMNS and getattr(self, name) is None:
            return True
        return name in self.null and bool(self.null[name][i])

    def row(self, i: int) -> TriangulationResult:
        """The :class:`~tritools.result.TriangulationResult` of problem i."""
        i = range(len(self))[i]
        kw = {name: _opt(getattr(self, name)[i]) for name in FLOAT_COLUMNS}
        kw.update({name: None if np.all(np.isnan(getattr(self, name)[i])) else getattr(self, name)[i]
                   for name in POINT_COLUMNS})
        kw.update({name: None if getattr(self, name)[i] < 0 else int(getattr(self, name)[i]) for name in INT_COLUMNS})
        kw.update({name: None if self._is_null(name, i) else bool(getattr(self, name)[i]) for name in BOOL_COLUMNS})
        kw.update({name: getattr(self, name)[i] for name in TEXT_COLUMNS + ("message", "attempts")})
        slots = self.slots(i)
        kw.update({name: None if self._is_null(name, i) else getattr(self, name)[i, slots] for name in VIEW_COLUMNS})
        kw["timings"] = {k: float(v[i]) for k, v in self.timings.items() if v[i] == v[i]}
        return TriangulationResult(status=self.status[i], **kw)

    def __getitem__(self, key):
        """A row for an integer; a :meth:`take` of the rows for a slice, an index array or a boolean mask."""
        if isinstance(key, (int, np.integer)):
            return self.row(int(key))
        if isinstance(key, slice):
            return self.take(np.arange(len(self))[key])
        return self.take(key)

    def __iter__(self):
        return (self.row(i) for i in range(len(self)))

    def results(self) -> list[TriangulationResult]:
        """Every row as a :class:`~tritools.result.TriangulationResult` (a list)."""
        return list(self)

    def __eq__(self, other) -> bool:
        """Equal rows (a list or tuple of rows compares row by row)."""
        if not isinstance(other, (TriangulationResults, list, tuple)):
            return NotImplemented
        if len(self) != len(other) or not all(a == b for a, b in zip(self, other)):
            return False
        return not isinstance(other, TriangulationResults) or \
            all(np.array_equal(self.slots(i), other.slots(i)) for i in range(len(self)))

    __hash__ = None

    def __repr__(self) -> str:
        counts = {}
        for s in self.status:
            counts[s.value] = counts.get(s.value, 0) + 1
        return f"TriangulationResults({len(self)} problems, {counts})"

    # ------------------------------------------------------------------ vectorised
    @property
    def certified(self) -> np.ndarray:
        """(M,) bool: status OPTIMAL or BEHIND_CAMERA (a certificate of global optimality)."""
        return np.fromiter((s.certified for s in self.status), bool, count=len(self))

    @property
    def gap(self) -> np.ndarray:
        """(M,) ``gamma_ub - gamma_lb`` (NaN where a bound is absent)."""
        return self.gamma_ub - self.gamma_lb

    # ------------------------------------------------------------------ building
    @classmethod
    def from_rows(cls, rows, n_views=None) -> TriangulationResults:
        """The record of ``rows`` (TriangulationResult objects); ``n_views`` the problems' view counts (default:
        the length of each row's per-view arrays, 0 without any).  ValueError naming the column whose per-view
        array does not have the row's length."""
        return cls(**_columns_of_rows(list(rows), n_views))

    @classmethod
    def concat(cls, parts: Sequence[TriangulationResults]) -> TriangulationResults:
        """The rows of ``parts``, one after the other (per-view columns padded to the widest part)."""
        parts = list(parts)
        if len(parts) == 1 and isinstance(parts[0], cls):
            return parts[0]                     # immutable: no copy
        return cls(**_concat_columns(parts))

    def take(self, index) -> TriangulationResults:
        """The rows at ``index`` (integer indices, in their order, or a boolean mask of length M)."""
        idx = np.asarray(index)
        if idx.dtype == bool:
            if idx.shape != (len(self),):
                raise ValueError(f"mask must have shape ({len(self)},), got {idx.shape}")
            idx = np.nonzero(idx)[0]
        elif idx.size == 0:
            idx = idx.astype(int)
        elif idx.dtype.kind not in "iu":
            raise TypeError(f"index must be integers or a boolean mask, got dtype {idx.dtype}")
        idx = idx.reshape(-1)
        if idx.size == len(self) and np.array_equal(idx, np.arange(len(self))):
            return self                         # immutable: no copy
        return type(self)(**_taken_columns(self, idx))

    def with_views(self, views) -> TriangulationResults:
        """The same rows with their per-view entries in the slots ``views`` (M, W') marks (e.g. the visibility
        mask of ``triangulate_points``); ``n_views`` becomes ``views.sum(1)`` (ValueError where a row with
        per-view data has another count)."""
        return type(self)(**_columns_with_views(self, _numbers("views", views, np.shape(views), bool)))

    def drop(self, *names: str) -> TriangulationResults:
        """The same rows with the columns ``names`` absent (per-view columns, ``attempts``, ``timings``, ``X_raw``
        ...): what a whole-model report keeps of each point (ValueError naming an unknown or required column)."""
        kw = {f.name: getattr(self, f.name) for f in fields(self)}
        for name in names:
            if name not in kw or name in ("method", "status", "n_views", "null"):
                raise ValueError(f"drop: {name!r} is not a column that can be dropped")
            kw[name] = {} if name == "timings" else None
        kw["null"] = {k: v for k, v in self.null.items() if k not in names}
        if all(kw[k] is None for k in VIEW_COLUMNS):
            kw["views"] = None
        return type(self)(**kw)

    # ------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        """The one JSON form: ``{"results": [row.to_dict(), ...], "views": [[slot, ...], ...], "width": W}``."""
        return {"results": [r.to_dict() for r in self], "views": [self.slots(i).tolist() for i in range(len(self))],
                "width": self.width}

    @classmethod
    def from_dict(cls, d: Mapping) -> TriangulationResults:
        """Inverse of :meth:`to_dict` (a list of row dicts is read as ``{"results": list}``)."""
        if isinstance(d, (list, tuple)):
            d = {"results": d}
        rows = [TriangulationResult.from_dict(r) for r in d["results"]]
        slots = d.get("views")
        if slots is None:
            return cls.from_rows(rows)
        if len(slots) != len(rows):
            raise ValueError(f"views must have one entry per result ({len(rows)}), got {len(slots)}")
        out = cls.from_rows(rows, [len(s) for s in slots])
        width = int(d.get("width", out.width))
        if width == out.width and all(list(s) == list(range(len(s))) for s in slots):
            return out
        mask = np.zeros((len(rows), width), bool)
        for i, s in enumerate(slots):
            mask[i, list(s)] = True
        return out.with_views(mask)


# ---------------------------------------------------------------------- column builders
def _row_counts(rows: list, n_views) -> np.ndarray:
    """n_views of each row: given, else the length of its first per-view array (0 without any)."""
    if n_views is not None:
        counts = _numbers("n_views", n_views, (len(rows),), int)
        return counts
    return np.array([next((len(getattr(r, k)) for k in VIEW_COLUMNS if getattr(r, k) is not None), 0)
                     for r in rows], int)


def _view_column(rows: list, name: str, counts: np.ndarray, W: int):
    """(padded (M, W, ...) array or None, null mask) of one per-view column of ``rows``."""
    tail, dtype, fill = VIEW_COLUMNS[name]
    values = [getattr(r, name) for r in rows]
    null = np.array([v is None for v in values], bool)
    if null.all():
        return None, null
    arr = np.full((len(rows), W) + tail, fill, dtype)
    for i, v in enumerate(values):
        if v is not None:
            if len(v) != counts[i]:
                raise _bad(name, f"of rows[{i}] has {len(v)} entries, but the row has n_views = {counts[i]}")
            arr[i, :counts[i]] = v
    return arr, null


def _columns_of_rows(rows: list, n_views) -> dict:
    for k, r in enumerate(rows):
        if not isinstance(r, TriangulationResult):
            raise TypeError(f"rows[{k}] must be a TriangulationResult, got {type(r).__name__}")
    M = len(rows)
    counts = _row_counts(rows, n_views)
    W = int(counts.max(initial=0))
    cols: dict = {name: [getattr(r, name) for r in rows] for name in TEXT_COLUMNS + ("status", "message", "attempts")}
    for name in POINT_COLUMNS:
        cols[name] = np.array([np.full(3, np.nan) if getattr(r, name) is None else getattr(r, name)
                               for r in rows], float).reshape(M, 3)
    for name in FLOAT_COLUMNS:
        cols[name] = np.array([np.nan if getattr(r, name) is None else getattr(r, name) for r in rows], float)
    for name in INT_COLUMNS:
        cols[name] = np.array([-1 if getattr(r, name) is None else getattr(r, name) for r in rows], int)
    null = {}
    for name in BOOL_COLUMNS:
        cols[name] = np.array([bool(getattr(r, name)) for r in rows], bool)
        null[name] = np.array([getattr(r, name) is None for r in rows], bool)
    for name in VIEW_COLUMNS:
        cols[name], null[name] = _view_column(rows, name, counts, W)
    keys = list(dict.fromkeys(k for r in rows for k in r.timings))
    cols["timings"] = {k: np.array([r.timings.get(k, np.nan) for r in rows], float) for k in keys}
    cols.update(n_views=counts, null=null)
    return cols


def _slot_mask(rec: TriangulationResults, W: int) -> np.ndarray:
    """(M, W) mask of the slots holding each row's per-view entries."""
    if rec.views is not None:
        return np.pad(rec.views, ((0, 0), (0, W - rec.views.shape[1])))
    return np.arange(W) < rec.n_views[:, None]


def _full_columns(rec: TriangulationResults, W: int, with_views: bool) -> dict:
    """Every column of ``rec`` explicit: per-view columns padded to W (absent ones filled, null everywhere),
    a null mask for every nullable column, ``views`` explicit when ``with_views``."""
    M, w0 = len(rec), rec.width
    names = TEXT_COLUMNS + POINT_COLUMNS + FLOAT_COLUMNS + INT_COLUMNS + BOOL_COLUMNS + \
        ("status", "message", "attempts", "n_views")
    cols = {name: None if name in _DEFAULTS and (M == 0 or _is_absent(name, getattr(rec, name))) else
            getattr(rec, name) for name in names}
    cols["timings"] = dict(rec.timings)
    null = {name: rec.null.get(name, np.zeros(M, bool)) for name in BOOL_COLUMNS}
    for name, (tail, dtype, fill) in VIEW_COLUMNS.items():
        arr = np.full((M, W) + tail, fill, dtype)
        value = getattr(rec, name)
        if value is not None:
            arr[:, :w0] = value
        null[name] = rec.null.get(name, np.zeros(M, bool)) if value is not None else np.ones(M, bool)
        cols[name] = arr
    cols["views"] = _slot_mask(rec, W) if with_views else None
    cols["null"] = null
    return cols


def _compact(cols: dict) -> dict:
    """Per-view columns null in every row become None (their mask goes)."""
    for name in VIEW_COLUMNS:
        if cols["null"][name].all():
            cols[name] = None
            del cols["null"][name]
    return cols


def _concat_columns(parts: list) -> dict:
    if not parts:
        return {"method": [], "status": []}
    W = max(p.width for p in parts)
    with_views = any(p.views is not None for p in parts)
    full = [_full_columns(p, W, with_views) for p in parts]
    out = {k: None if all(f[k] is None for f in full) else
           np.concatenate([_absent(k, len(p)) if f[k] is None else f[k] for f, p in zip(full, parts)])
           for k in full[0] if k not in ("timings", "null", "views")}
    out["views"] = np.concatenate([f["views"] for f in full]) if with_views else None
    out["null"] = {k: np.concatenate([f["null"][k] for f in full]) for k in full[0]["null"]}
    keys = list(dict.fromkeys(k for p in parts for k in p.timings))
    out["timings"] = {k: np.concatenate([p.timings.get(k, np.full(len(p), np.nan)) for p in parts]) for k in keys}
    return _compact(out)


def _taken_columns(rec: TriangulationResults, idx: np.ndarray) -> dict:
    cols = _full_columns(rec, rec.width, rec.views is not None)
    out = {k: (None if v is None else v[idx]) for k, v in cols.items() if k not in ("timings", "null")}
    out["timings"] = {k: v[idx] for k, v in rec.timings.items()}
    out["null"] = {k: v[idx] for k, v in cols["null"].items()}
    return _compact(out)


def _columns_with_views(rec: TriangulationResults, views: np.ndarray) -> dict:
    """Columns of ``rec`` with the per-view entries moved to the slots of ``views`` (M, W')."""
    M = len(rec)
    if views.ndim != 2 or views.shape[0] != M:
        raise _bad("views", f"must have shape ({M}, W), got {views.shape}")
    counts = views.sum(axis=1)
    cols = _full_columns(rec, rec.width, False)
    has = ~np.all([cols["null"][k] for k in VIEW_COLUMNS], axis=0)
    bad = np.nonzero(has & (counts != rec.n_views))[0]
    if bad.size:
        i = int(bad[0])
        raise _bad("views", f"marks {counts[i]} views of row {i}, whose per-view arrays have {rec.n_views[i]}")
    src, dst = _slot_mask(rec, rec.width) & has[:, None], views & has[:, None]
    for name, (tail, dtype, fill) in VIEW_COLUMNS.items():
        arr = np.full(views.shape + tail, fill, dtype)
        arr[dst] = cols[name][src]
        cols[name] = arr
    cols.update(views=views, n_views=counts)
    return _compact(cols)
