"""Property/fuzz test of the command line (issue #13): random bytes and mutated valid files (CSV, params YAML,
MCAP) fed to ``hyst fit``, ``compare``, ``diagnose`` and ``simulate``. Every run must end with exit 0 (or 3,
diagnose's "unexplained") or 2 with one message, never an uncaught exception (a traceback), and no file may
appear outside the run's own output path. Seeded; ``HYST_FUZZ_N`` sets the runs per command (default 1000).
"""
from __future__ import annotations

import os
import random
from pathlib import Path

import numpy as np
import pytest

from hyst_model.cli.main import main

pytestmark = pytest.mark.slow
N = int(os.environ.get("HYST_FUZZ_N", "1000"))


def _mutate(data: bytes, rng: random.Random) -> bytes:
    """One to four random edits: flip, insert, delete, duplicate a span, truncate; or plain random bytes."""
    if rng.random() < 0.1:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(0, 300)))
    b = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        if not b:
            break
        i = rng.randrange(len(b))
        op = rng.randrange(6)
        if op == 0:
            b[i] = rng.randrange(256)
        elif op == 1:
            b[i:i] = bytes(rng.choice(b"0123456789.,-e\n\r\t :#abcnaninf\x00\xff") for _ in range(rng.randint(1, 8)))
        elif op == 2:
            del b[i:i + rng.randint(1, 40)]
        elif op == 3:
            j = rng.randrange(len(b))
            b[i:i] = b[j:j + rng.randint(1, 200)]
        elif op == 4:
            del b[i:]
        else:
            b[i] = rng.choice(b"-9.e")
    return bytes(b)


@pytest.fixture(scope="module")
def valid(tmp_path_factory):
    d = tmp_path_factory.mktemp("valid")
    t = np.arange(400) * 1e-3
    u = 75 - 70 * np.cos(2 * np.pi * 2 * t)
    y = 2e-7 * u
    csv = d / "d.csv"
    np.savetxt(csv, np.c_[t, u, y], delimiter=",", header="t,u,y", comments="")
    inp = d / "u.csv"
    np.savetxt(inp, np.c_[t, u], delimiter=",", header="t,u", comments="")
    params = d / "p.yaml"
    assert main(["fit", str(csv), "--quiet", "--out", str(params)]) == 0
    from hyst_model.io.bag import write_state_bag
    bag = d / "b.mcap"
    write_state_bag(bag, t, u, y, compress=False)
    return {"csv": csv.read_bytes(), "input": inp.read_bytes(), "params": params.read_bytes(),
            "mcap": bag.read_bytes(), "dir": d}


def _run(argv: list[str], work: Path, capsys) -> None:
    before = {p for p in work.rglob("*")}
    try:
        rc = main(argv)
    except SystemExit as ex:  # argparse
        rc = ex.code
    err = capsys.readouterr().err
    assert rc in (0, 2, 3), (argv, rc, err[-500:])
    assert "Traceback" not in err, (argv, err[-2000:])
    new = {p for p in work.rglob("*")} - before
    allowed = {work / "out.yaml", work / "out.csv"}
    assert new <= allowed, (argv, sorted(map(str, new - allowed)))


@pytest.mark.parametrize("command", ["fit", "compare", "diagnose", "simulate"])
def test_mutated_inputs_never_crash(command, valid, tmp_path, capsys):
    rng = random.Random(f"hyst-fuzz-{command}")
    for i in range(N):
        work = tmp_path / f"r{i}"
        work.mkdir()
        kind = rng.choice(["csv", "mcap"]) if command != "simulate" else "input"
        data = work / ("d.mcap" if kind == "mcap" else "d.csv")
        params = work / "p.yaml"
        mutate_params = command in ("compare", "simulate") and rng.random() < 0.5
        data.write_bytes(valid[kind] if mutate_params else _mutate(valid[kind], rng))
        params.write_bytes(_mutate(valid["params"], rng) if mutate_params else valid["params"])
        if command == "fit":
            argv = ["fit", str(data), "--quiet", "--out", str(work / "out.yaml")]
        elif command == "compare":
            argv = ["compare", str(data), "--params", str(params), "--json"]
        elif command == "diagnose":
            argv = ["diagnose", str(data), "--quiet", "--json", "--out", str(work / "out.yaml")]
        else:
            argv = ["simulate", "--params", str(params), "--input", str(data), "--out", str(work / "out.csv")]
        _run(argv, work, capsys)
