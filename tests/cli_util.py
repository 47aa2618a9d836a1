"""Helpers shared by the CLI tests: run ``tritools.cli.app.main`` in-process and write problem files."""
import json

from tritools.cli import app as cli


def run(argv, capsys):
    """(exit code, stdout, stderr) of ``tritools <argv>``."""
    rc = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def write(tmp_path, doc, name="problems.json"):
    """``doc`` (bytes, text, or a JSON-able object) written to ``tmp_path / name``."""
    p = tmp_path / name
    if isinstance(doc, bytes):
        p.write_bytes(doc)
    else:
        p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p
