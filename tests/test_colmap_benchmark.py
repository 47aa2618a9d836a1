"""benchmarks/colmap.py runs end to end on a tiny model (three child processes) and prints its table."""
from __future__ import annotations

import importlib.util
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_colmap_benchmark_script_on_a_tiny_model(capsys, tmp_path):
    spec = importlib.util.spec_from_file_location("colmap_bench", ROOT / "benchmarks" / "colmap.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--points", "300", "--cameras", "OPENCV", "--images", "6", "--pycolmap", "40",
                     "--json", str(tmp_path / "raw.json")]) == 0
    out = capsys.readouterr().out
    assert "| points | camera | observations |" in out and "| 300 | OPENCV |" in out
    import json
    (raw,) = json.loads((tmp_path / "raw.json").read_text())
    run = raw["run"]
    assert run["n_points"] == 300 and run["n_certified"] >= 295 and run["peak_rss_mib"] > 0
    assert run["rms_gamma_out"] < run["rms_gamma_in"]
    pc = raw["pycolmap"]
    assert "skipped" in pc or pc["ours_not_worse"] == pc["compared"]
