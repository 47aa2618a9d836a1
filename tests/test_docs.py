"""Run every ```python code block of docs/*.md: per file, in order, in one fresh namespace.

A block that raises (including a failed ``assert``) fails the test for its file, with the
block's number and first line in the message.
"""
import pathlib
import re

import pytest

DOCS = pathlib.Path(__file__).resolve().parents[1] / "docs"
FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)


def python_blocks(text):
    return [m.group(1) for m in FENCE.finditer(text)]


def test_fence_parser():
    text = "intro\n```python\na = 1\n```\n\n```\nnot python\n```\n```python\nb = a + 1\n```\n"
    assert python_blocks(text) == ["a = 1\n", "b = a + 1\n"]


DOC_FILES = sorted(DOCS.glob("*.md"))


def test_docs_exist():
    assert any(p.name == "sospoly.md" for p in DOC_FILES)
    assert python_blocks((DOCS / "sospoly.md").read_text())


@pytest.mark.parametrize("path", DOC_FILES, ids=lambda p: p.name)
def test_doc_code_blocks_run(path, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)              # blocks that write files do so in a scratch directory
    namespace = {"__name__": f"docs_{path.stem}"}
    for k, block in enumerate(python_blocks(path.read_text())):
        code = compile(block, f"{path.name}[block {k}]", "exec")
        try:
            exec(code, namespace)
        except Exception as exc:  # pragma: no cover - message path
            first = block.strip().splitlines()[0] if block.strip() else ""
            pytest.fail(f"{path.name} block {k} ({first!r}) raised {type(exc).__name__}: {exc}")
