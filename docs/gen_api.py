"""Generate docs/api.md, the API reference, from the docstrings of the public names.

    python docs/gen_api.py            # rewrite docs/api.md
    python docs/gen_api.py --check    # exit 1 if docs/api.md is out of date

The public names are those in ``__all__`` of ``sospoly`` and ``tritools`` and of the
submodules listed in :data:`SUBMODULES` (a module that does not exist yet is skipped,
so a name added to an ``__all__`` appears as soon as this script is rerun).  Each
name is documented once, where it first appears; later modules link to it.  For each
name: its signature, the docstring's description (up to the first numpy-style section
header) as prose, and its Parameters / Returns / Raises / Attributes sections verbatim.
Classes also list their members (enum values, dataclass fields, public methods and
properties defined in the class itself).  The output is deterministic: names are
sorted, memory addresses and set orderings never reach the text.
"""
from __future__ import annotations

import argparse
import dataclasses
import enum
import importlib
import inspect
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "api.md"

#: documented first, in this order: the packages' top-level names.
PACKAGES = ("sospoly", "tritools")
#: public submodules whose ``__all__`` is documented too (missing ones are skipped).
SUBMODULES = (
    "sospoly.analysis.verify",
    "sospoly.testing",
    "tritools.model.regions",
    "tritools.model.geometry",
    "tritools.model.constraints",
    "tritools.solve.batch",
    "tritools.baselines",
    "tritools.scene",
    "tritools.io.oxford",
    "tritools.plot",
    "tritools.io.colmap",
    "tritools.sfm",
)
#: numpy-docstring sections reproduced verbatim (others, e.g. Examples, are left out).
KEPT_SECTIONS = ("Parameters", "Returns", "Yields", "Raises", "Attributes")
#: the longest default value or constant repr printed before it is abbreviated.
MAX_REPR = 70
#: the same for a documented constant (shown on its own line).
MAX_CONSTANT_REPR = 400

_SECTION_RE = re.compile(r"^(\w[\w ]*)\n(-{3,}|={3,})$", re.M)
_ADDRESS_RE = re.compile(r" at 0x[0-9a-fA-F]+")


# --------------------------------------------------------------------------- discovery
def import_optional(name: str):
    """The module ``name``, or None when it does not exist (other import errors propagate)."""
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name == name:
            return None
        raise


def modules() -> list:
    """The documented modules, in order (missing optional submodules left out)."""
    out = []
    for name in PACKAGES + SUBMODULES:
        mod = import_optional(name)
        if mod is not None:
            out.append(mod)
    return out


def public_names(mod) -> list[str]:
    """``mod.__all__`` sorted case-insensitively (the module's declared public API)."""
    return sorted(getattr(mod, "__all__", ()), key=lambda n: (n.lower(), n))


def is_documentable(obj) -> bool:
    """Classes and functions carry docstrings; constants cannot."""
    return inspect.isclass(obj) or inspect.isroutine(obj)


def own_docstring(obj) -> str:
    """The object's own docstring, cleaned; "" when it has none.

    Inherited class docstrings and the ``Name(field, ...)`` text that ``dataclasses``
    fills in for undocumented dataclasses do not count.
    """
    if inspect.isclass(obj):
        doc = vars(obj).get("__doc__")
        if not doc or doc.startswith(obj.__name__ + "("):
            return ""
        if isinstance(obj, enum.EnumMeta) and doc.strip() == "An enumeration.":
            return ""
        return inspect.cleandoc(doc)
    doc = getattr(obj, "__doc__", None)
    return inspect.cleandoc(doc) if doc else ""


def missing_docstrings() -> list[str]:
    """Qualified public names (classes and functions) without their own docstring."""
    missing = []
    for mod in modules():
        for name in public_names(mod):
            obj = getattr(mod, name)
            if is_documentable(obj) and not own_docstring(obj):
                missing.append(f"{mod.__name__}.{name}")
    return missing


# --------------------------------------------------------------------------- formatting
def short_repr(value, module=None, limit: int = MAX_REPR) -> str:
    """A deterministic, short repr of a default value or constant."""
    if isinstance(value, enum.Enum):
        return f"{type(value).__name__}.{value.name}"
    if isinstance(value, (set, frozenset)):
        text = "{" + ", ".join(sorted(short_repr(v) for v in value)) + "}"
    else:
        text = _ADDRESS_RE.sub("", repr(value))
    if len(text) > limit:
        if module is not None:                     # a named module-level constant: use its name
            for gname, gval in sorted(vars(module).items()):
                if gval is value and gname.isupper():
                    return gname
        text = f"<{type(value).__name__}>"
    return text


def signature(obj, name: str) -> str | None:
    """``name(param=default, ...)``; None when Python cannot introspect it."""
    try:
        sig = inspect.signature(obj)
    except (TypeError, ValueError):
        return None
    module = sys.modules.get(getattr(obj, "__module__", ""), None)
    params = []
    star_done = False
    for p in sig.parameters.values():
        if p.kind == p.VAR_POSITIONAL:
            star_done = True
            text = "*" + p.name
        elif p.kind == p.VAR_KEYWORD:
            text = "**" + p.name
        else:
            if p.kind == p.KEYWORD_ONLY and not star_done:
                params.append("*")
                star_done = True
            text = p.name
            if p.default is not p.empty:
                text += "=" + short_repr(p.default, module)
        params.append(text)
    return f"{name}({', '.join(params)})"


def split_sections(doc: str) -> tuple[str, dict[str, str]]:
    """(description, {section title: body}) of a numpy-style docstring."""
    matches = list(_SECTION_RE.finditer(doc))
    if not matches:
        return doc.strip(), {}
    desc = doc[: matches[0].start()].strip()
    sections = {}
    for k, m in enumerate(matches):
        end = matches[k + 1].start() if k + 1 < len(matches) else len(doc)
        sections[m.group(1).strip()] = doc[m.end():end].strip("\n")
    return desc, sections


def _rst_to_md(text: str) -> str:
    text = re.sub(r":(?:func|class|meth|mod|data|attr|exc):`~?([^`]+)`", r"`\1`", text)
    return text.replace("``", "`")


def description_md(desc: str) -> list[str]:
    """The description as markdown: prose paragraphs joined into lines, lists kept line by
    line, indented or tabular paragraphs (and doctests) in a text fence."""
    out = []
    for para in re.split(r"\n\s*\n", desc.strip()):
        lines = para.splitlines()
        if not lines:
            continue
        if lines[0].lstrip().startswith(">>>"):
            continue                                # examples live in docs/*.md, where they run
        verbatim = any(ln.startswith((" ", "\t")) for ln in lines[1:]) or \
            any(re.fullmatch(r"[=\- ]{3,}", ln.strip()) for ln in lines) or para.lstrip().startswith("|")
        if verbatim:
            out += ["```text", *[ln.rstrip() for ln in lines], "```", ""]
        elif (re.match(r"\s*([*-]|\d+\.)\s", lines[0]) or lines[0].startswith("  ")) and \
                any(re.match(r"\s*([*-]|\d+\.)\s", ln) for ln in lines[1:]):
            out += [_rst_to_md(ln.rstrip()) for ln in lines] + [""]
        else:
            out += [_rst_to_md(" ".join(ln.strip() for ln in lines)), ""]
    return out


def anchor(heading: str) -> str:
    """GitHub's anchor for a markdown heading."""
    return re.sub(r"[^\w\- ]", "", heading.lower()).replace(" ", "-")


def _first_line(obj) -> str:
    first = re.split(r"\n\s*\n", split_sections(own_docstring(obj))[0])[0]
    return _rst_to_md(" ".join(ln.strip() for ln in first.splitlines()))


def class_members(cls) -> list[str]:
    """Markdown bullet lines: enum values, dataclass fields, own public methods/properties."""
    out = []
    if isinstance(cls, enum.EnumMeta):
        for member in cls:
            out.append(f"- `{member.name}` = `{member.value!r}`")
        return out
    fields = [f.name for f in dataclasses.fields(cls)] if dataclasses.is_dataclass(cls) else []
    public_fields = [name for name in fields if not name.startswith("_")]
    if public_fields:
        out.append("- fields: " + ", ".join(f"`{name}`" for name in public_fields))
    for name, attr in vars(cls).items():
        if name.startswith("_") or name in fields:
            continue
        if isinstance(attr, property):
            line = f"- `{name}` (property)"
            func = attr
        elif isinstance(attr, (staticmethod, classmethod)):
            func = attr.__func__
            sig = signature(func, name)
            if sig and isinstance(attr, classmethod):
                sig = sig.replace("(cls, ", "(").replace("(cls)", "()")
            line = f"- `{sig or name}` ({type(attr).__name__})"
        elif inspect.isfunction(attr):
            func = attr
            sig = signature(attr, name)
            if sig:
                sig = sig.replace("(self, ", "(").replace("(self)", "()")
            line = f"- `{sig or name}`"
        else:
            continue
        summary = _first_line(func)
        out.append(line + (f": {summary}" if summary else ""))
    return out


def document(obj, qualname: str) -> list[str]:
    """Markdown lines documenting one public object under the heading ``qualname``."""
    lines = [f"### `{qualname}`", ""]
    short = qualname.rsplit(".", 1)[-1]
    if not is_documentable(obj):
        lines += ["```text", f"{short} = {short_repr(obj, limit=MAX_CONSTANT_REPR)}", "```", ""]
        return lines
    if inspect.isclass(obj):
        bases = [b for b in obj.__bases__ if b is not object]
        kind = "enum" if isinstance(obj, enum.EnumMeta) else \
            "exception" if issubclass(obj, BaseException) else "class"
        sig = None if kind == "enum" else signature(obj, short)
        head = f"{kind} {sig or short}"
        if bases:
            head += "  # bases: " + ", ".join(b.__qualname__ for b in bases)
    else:
        head = signature(obj, short) or short
    lines += ["```text", head, "```", ""]
    doc = own_docstring(obj)
    if not doc:
        lines += ["*(no docstring)*", ""]
    else:
        desc, sections = split_sections(doc)
        lines += description_md(desc)
        home = sys.modules.get(getattr(obj, "__module__", ""))
        if "module docstring" in desc and home is not None and home.__doc__:
            lines += [f"From the docstring of `{home.__name__}`:", ""]
            lines += description_md(split_sections(inspect.cleandoc(home.__doc__))[0])
        kept = [(t, b) for t, b in sections.items() if t in KEPT_SECTIONS]
        if kept:
            lines.append("```text")
            for title, body in kept:
                lines += [title, "-" * len(title), *[ln.rstrip() for ln in body.splitlines()], ""]
            lines[-1:] = ["```", ""]
    if inspect.isclass(obj):
        members = class_members(obj)
        if members:
            lines += members + [""]
    return lines


def generate() -> str:
    """The full text of docs/api.md."""
    mods = modules()
    seen: dict[int, str] = {}            # id(object) -> qualified name where it is documented
    body: list[str] = []
    toc = []
    for mod in mods:
        heading = f"`{mod.__name__}`"
        toc.append(f"- [{mod.__name__}](#{anchor(heading)})")
        body += [f"## {heading}", ""]
        summary = split_sections(inspect.cleandoc(mod.__doc__ or ""))[0]
        if summary:
            body += description_md(re.split(r"\n\s*\n", summary)[0])
        for name in public_names(mod):
            obj = getattr(mod, name)
            qual = f"{mod.__name__}.{name}"
            key = id(obj)
            if is_documentable(obj) and key in seen:
                target = seen[key]
                body += [f"- `{name}`: see [`{target}`](#{anchor('`' + target + '`')})", ""]
                continue
            if is_documentable(obj):
                seen[key] = qual
            body += document(obj, qual)
    head = [
        "# API reference",
        "",
        "<!-- generated by docs/gen_api.py; do not edit by hand -->",
        "Generated by `python docs/gen_api.py` from the docstrings of the names in `__all__` of",
        "`sospoly`, `tritools` and the submodules listed in the script; each object is documented",
        "once, where it first appears. `tests/test_api_docs.py` fails when this page is out of date.",
        "Worked examples are in the other pages of [the documentation](index.md).",
        "",
        *toc,
        "",
    ]
    text = "\n".join(head + body)
    return re.sub(r"\n{3,}", "\n\n", text).rstrip() + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/api.md is out of date")
    args = ap.parse_args(argv)
    text = generate()
    if args.check:
        current = OUT.read_text() if OUT.exists() else ""
        if current != text:
            print(f"{OUT} is out of date: run `python docs/gen_api.py`", file=sys.stderr)
            return 1
        return 0
    OUT.write_text(text)
    print(f"wrote {OUT} ({len(text.splitlines())} lines)")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
