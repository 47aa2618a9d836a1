"""Run every ```python code block of docs/*.md and README.md: per file, in order, in one fresh namespace.

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


DOC_FILES = sorted(DOCS.glob("*.md")) + [DOCS.parent / "README.md"]


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


def test_readme_starts_with_the_two_commands_and_ci_runs_the_test_command():
    root = DOCS.parent
    readme = (root / "README.md").read_text()
    first_block = re.search(r"```bash\n(.*?)```", readme, re.S).group(1).strip().splitlines()
    assert first_block[0] == "python -m pip install . && python -m tritools example 4"
    test_cmd = first_block[1]
    assert test_cmd == 'python -m pip install -e ".[test]" && python -m pytest -q'
    ci = (root / ".ci" / "run").read_text().splitlines()
    assert test_cmd in ci, ".ci/run must run exactly the README's test command"
