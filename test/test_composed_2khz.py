"""hyst_loop_node: sim + reference + controller in one process at 2 kHz.

Lockstep makes the run deterministic on a loaded machine (the achieved real-time rate is measured by
bench/bench_control.py, never asserted in tests): every state is answered, DPPC and DMRAC track at the noise
floor like the in-process loop, the schedule switches algorithms through the parameter callbacks.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow, pytest.mark.ros]
EXE = Path(sys.executable).parent / "hyst_loop_node"


def _run(*extra: str, timeout: float = 120.0) -> dict:
    proc = subprocess.run([str(EXE), "--schedule", "dppc:1.5,dmrac:1.5,pid:1.5", "--summary-json", "--ros-args",
                           "-p", "rate:=2000.0", "-p", "hyst_sim:mode:=lockstep",
                           # a lockstep loop may pause on a loaded machine: that is not a lost stage
                           "-p", "hyst_controller:watchdog_periods:=1000000", *extra],
                          env=dict(os.environ), capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-2000:]
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")][-1]
    return json.loads(line)


def test_composed_lockstep_2khz_tracks_at_the_noise_floor_and_switches():
    out = _run("-p", "hyst_controller:reference:=sine:10")
    tr, ctl, sim = out["tracking"], out["controller"], out["sim"]
    assert set(tr) == {"dppc", "dmrac", "pid"} and ctl["switches"] == 2
    # lockstep: one sample per command (± the one in flight when the run stops), none stale
    assert sim["stale"] == 0 and abs(ctl["commands"] - sim["samples"]) <= 2 and ctl["commands"] == ctl["states"]
    assert tr["dppc"]["rmse"] < 10e-9 and tr["dmrac"]["rmse"] < 10e-9  # 2 nm sensor: noise floor
    assert tr["pid"]["rmse"] > 5 * tr["dppc"]["rmse"]  # the baseline lags a 10 Hz sine
    assert ctl["watchdog_trips"] == 0 and ctl["bad_states"] == 0


def test_bad_schedule_is_refused_with_a_reason():
    proc = subprocess.run([str(EXE), "--schedule", "dppc:x"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "ALGORITHM:SECONDS" in proc.stderr


def test_a_schedule_segment_waits_for_its_first_tracked_sample_within_a_bound():
    """On a loaded machine start-up and the settling skip after a switch can eat a whole wall-clock segment (the
    demo beside CI once tracked DPPC for 0 samples): a segment lasts its seconds and until its algorithm tracked a
    sample, at most SEGMENT_STRETCH times its seconds."""
    from hyst_bringup.composed import SEGMENT_STRETCH, _segment_done

    class Ctl:
        def __init__(self, n: int) -> None:
            self.n = n

        def tracking_summary(self) -> dict:
            return {"dppc": {"samples": self.n}}

    assert not _segment_done(Ctl(500), ("dppc", 2.0), 1.9)
    assert _segment_done(Ctl(500), ("dppc", 2.0), 2.0)
    assert not _segment_done(Ctl(0), ("dppc", 2.0), 2.0) and not _segment_done(Ctl(0), ("pid", 2.0), 5.9)
    assert _segment_done(Ctl(0), ("dppc", 2.0), SEGMENT_STRETCH * 2.0)


def test_composed_realtime_samples_the_reference_in_process():
    """Realtime: the controller takes the reference node's trajectory in process (no /stage/reference message per
    sample); the loop tracks the sine whatever the machine's timing: a slow sine (0.5 Hz, 31 µm/s at most) moves
    0.3 µm in a 10 ms stall, while a wrong time base leaves an error of the sine's own size (µm)."""
    proc = subprocess.run([str(EXE), "--schedule", "dppc:1.5", "--summary-json", "--reference-rate", "100",
                           "--ros-args", "-p", "rate:=2000.0", "-p", "shape:=sine", "-p", "frequency:=0.5",
                           "-p", "hyst_controller:watchdog_periods:=1000000"],
                          env=dict(os.environ), capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads([ln for ln in proc.stdout.splitlines() if ln.startswith("{")][-1])
    tr, ctl = out["tracking"]["dppc"], out["controller"]
    assert tr["samples"] > 0 and ctl["bad_refs"] == 0
    assert tr["rmse"] < 2.5e-6


@pytest.mark.parametrize("argv,opt", [(["--reference-rate", "0"], "--reference-rate"),
                                      (["--seconds", "-1"], "--seconds"),   # ran 0 s and exited 0
                                      (["--seconds", "nan"], "--seconds"),  # ran until a signal
                                      (["--wait-subscribers", "-3"], "--wait-subscribers")])
def test_a_bad_option_is_refused(argv, opt):
    proc = subprocess.run([str(EXE), *argv], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and opt in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.parametrize("bad,why", [("params_file:=/nonexistent.yaml", "no such params file"),
                                     ("rate:=-5.0", "rate")])
def test_a_bad_start_up_parameter_is_one_line_and_exit_2(bad, why):
    """As each node alone (run_node): the loop gave a traceback and exit 1."""
    proc = subprocess.run([str(EXE), "--seconds", "1", "--ros-args", "-p", bad], env=dict(os.environ),
                          capture_output=True, text=True, timeout=120)
    err = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and len(err) == 1 and err[0].startswith("hyst_loop_node: error:") and why in err[0]


def test_one_sigint_stops_the_loop_cleanly_with_its_summary():
    """A SIGINT raised inside a callback printed '[FATAL] Exception in callback' (2 of 7 stops); now a flag."""
    import signal
    import threading

    proc = subprocess.Popen([str(EXE), "--summary-json", "--ros-args", "-p", "rate:=1000.0"], env=dict(os.environ),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    err: list[str] = []
    ready = threading.Event()

    def read() -> None:
        for line in proc.stderr:
            err.append(line)
            if "controller ready" in line:  # the nodes are built: the loop's own signal handling is in place
                ready.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert ready.wait(timeout=120), "".join(err)[-2000:]
        proc.send_signal(signal.SIGINT)
        out = proc.stdout.read()
        proc.wait(timeout=120)
        reader.join(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    text = "".join(err)
    assert proc.returncode == 0, text[-2000:]
    assert "Traceback" not in text and "FATAL" not in text, text[-2000:]
    assert json.loads([ln for ln in out.splitlines() if ln.startswith("{")][-1])["controller"]


def test_lockstep_with_the_reference_node_runs_on_the_stages_time_and_repeats():
    """The reference node's timer ran on the wall clock: a lockstep loop followed a 4.7 Hz sine for a 10 Hz one,
    and two runs gave 26 and 44 nm. On the stage's time, two runs give the same figures to the last digit."""
    def once() -> dict:
        proc = subprocess.run([str(EXE), "--seconds", "0.5", "--summary-json", "--schedule", "pid:0.5", "--ros-args",
                               "-p", "hyst_sim:mode:=lockstep", "-p", "rate:=2000.0", "-p", "shape:=sine",
                               "-p", "frequency:=10.0", "-p", "hyst_controller:watchdog_periods:=1000000"],
                              env=dict(os.environ), capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr[-2000:]
        return json.loads([ln for ln in proc.stdout.splitlines() if ln.startswith("{")][-1])["tracking"]["pid"]
    a, b = once(), once()
    assert a == b and a["samples"] > 400
