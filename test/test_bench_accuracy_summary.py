"""The accuracy benchmark's summary line for the issue's own "never a bare none" condition (no diagnosis run:
rows as ``run_case`` writes them)."""
from __future__ import annotations

import importlib.util
from pathlib import Path


def _bench():
    spec = importlib.util.spec_from_file_location(
        "bench_acc_summary", Path(__file__).resolve().parents[1] / "bench" / "bench_diagnose_accuracy.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _row(case: str, named: str, base_over_noise: float, unexplained=None) -> dict:
    return {"case": case, "named": [named], "base_over_noise": base_over_noise, "unexplained": unexplained}


def test_a_bare_none_on_a_large_base_error_is_counted_and_named():
    mod = _bench()
    rows = [_row("a", "none", 12.0),                         # bare: counted and named
            _row("b", "none", 12.0, {"kind": "loop shape"}),  # none with the remainder reported: not bare
            _row("c", "drift", 30.0),                        # an effect named: not bare
            _row("d", "none", 1.2),                          # at the floor: outside the condition
            {"case": "e", "named": ["error"], "error": "FitError: x", "base_over_noise": 40.0}]
    line = mod.bare_none_line(rows)
    assert "1 of 3 such records (a)" in line


def test_no_bare_none_reads_zero():
    mod = _bench()
    line = mod.bare_none_line([_row("b", "unexplained", 9.0, {"kind": "outside"}), _row("d", "none", 4.9)])
    assert line.endswith("0 of 1 such records")
