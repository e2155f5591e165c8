"""Controller step cost per algorithm, and closed-loop timing over ROS: 1 kHz across processes, 2 kHz composed.

* Step cost: ``Controller.step`` (law + limits, numba kernels warm) timed over 20 000 samples of a recorded 10 Hz
  closed loop; median and p99 of blocks of 1000 calls, per call.
* Loops (realtime, 5 s each): the sim and the controller (internal ``reference:=sine:5``) as two processes at
  1 kHz, and ``hyst_loop_node`` (sim + reference + controller in one process, EventsExecutor) at 2 kHz. A third
  process records ``/stage/state`` and ``/stage/command``: achieved state rate, round trip = receive time of the
  command minus receive time of the state it answers (matched by stamp), missed periods = Σ(gap/period − 1) over
  state gaps longer than 1.5 periods, unanswered = states without a command (the recorder's own drops count
  here too: on a loaded machine these are upper bounds).

Run: ``python bench/bench_control.py``; prints markdown. Figures depend on machine load (``os.getloadavg``
is printed with them).
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from hyst_bringup.loop import default_plant, run_closed_loop
from hyst_common.runtime import stop_processes

from hyst_control.controllers import ALGORITHMS, make_controller
from hyst_model.core import pea_default

BIN = Path(sys.executable).parent
SIM = ("import sys, rclpy\nfrom rclpy.experimental import EventsExecutor\nfrom hyst_sim.sim_node import SimNode\n"
       "rclpy.init(args=sys.argv)\nn = SimNode()\nex = EventsExecutor()\nex.add_node(n)\n"
       "try:\n    while rclpy.ok():\n        ex.spin_once(timeout_sec=0.1)\nexcept BaseException:\n    pass\n"
       "finally:\n    n.destroy_node()\n    rclpy.try_shutdown()\n")
RECORDER = r'''
import json, sys, time, rclpy
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from sensor_msgs.msg import JointState
rclpy.init()
n = Node("bench_recorder")
S, C = {}, {}
key = lambda m: m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
n.create_subscription(JointState, "/stage/state", lambda m: S.setdefault(key(m), time.monotonic()), 1000)
n.create_subscription(JointState, "/stage/command", lambda m: C.setdefault(key(m), time.monotonic()), 1000)
ex = EventsExecutor(); ex.add_node(n)
deadline, dur = float(sys.argv[1]), float(sys.argv[2])
# Ready by discovery and traffic, not by a fixed wait: the loop is up once states AND answering commands flow.
t0 = time.monotonic()
ready = None
while time.monotonic() - t0 < deadline:
    ex.spin_once(timeout_sec=0.01)
    if ready is None and len(S) > 50 and len(C) > 50:
        ready = time.monotonic()
    if ready is not None and time.monotonic() - ready > 1.0:  # one more second to let start-up transients pass
        break
up = time.monotonic() - t0
S.clear(); C.clear()
t1 = time.monotonic()
if ready is not None:
    while time.monotonic() - t1 < dur: ex.spin_once(timeout_sec=0.01)
json.dump({"S": sorted(S.items()), "C": sorted(C.items()), "dur": dur, "ready": ready is not None, "up": up},
          open(sys.argv[3], "w"))
'''


def step_cost() -> str:
    res = run_closed_loop(make_controller("dppc", pea_default(), 5e-4), "sine:10", 10.0,
                          plant=default_plant(2000.0))
    r, y = res.r, np.concatenate([[res.y[0]], res.y[:-1]])
    lines = ["| algorithm | step cost p50 (µs) | p99 of 1000-call blocks (µs) |", "|---|---|---|"]
    for alg in ALGORITHMS:
        c = make_controller(alg, pea_default(), 5e-4)
        c.reset(y[0], 60.0, r[0])
        for k in range(2000):  # warm-up (numba dispatch, caches)
            c.step(r[k], y[k])
        blocks = []
        for b in range(20):
            t0 = time.perf_counter()
            for k in range(b * 1000, (b + 1) * 1000):
                c.step(r[k], y[k])
            blocks.append((time.perf_counter() - t0) / 1000 * 1e6)
        lines.append(f"| {alg} | {np.median(blocks):.1f} | {np.percentile(blocks, 99):.1f} |")
    return "\n".join(lines)


def _analyse(path: str, rate: float) -> dict:
    d = json.load(open(path))
    S, C = dict(d["S"]), dict(d["C"])
    if not d.get("ready") or len(S) < 10:
        return {"rate": 0.0, "p50": float("nan"), "p99": float("nan"), "missed": float("nan"), "unanswered": 0,
                "note": f"NOT MEASURED: the loop was not running within {d.get('up', 0):.0f} s (no states and "
                        "commands seen)"}
    st = np.array(sorted(S))
    gaps = np.diff(st) * 1e-9 * rate
    rt = np.array([C[k] - S[k] for k in S if k in C]) * 1e3
    span = (st[-1] - st[0]) * 1e-9  # the sim stamps its ticks: the span is the stage's own time base
    return {"rate": (len(st) - 1) / span if span > 0 else float("nan"),
            "p50": float(np.percentile(rt, 50)) if rt.size else float("nan"),
            "p99": float(np.percentile(rt, 99)) if rt.size else float("nan"),
            "missed": float(np.sum(gaps[gaps > 1.5] - 1.0)), "unanswered": int(sum(k not in C for k in S)),
            "up": float(d.get("up", 0.0))}


def _loop(cmds: list[list[str]], rate: float, seconds: float = 5.0) -> dict:
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               ROS_DOMAIN_ID=os.environ.get("ROS_DOMAIN_ID", str(10 + os.getpid() % 80)))
    procs = [subprocess.Popen(c, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for c in cmds]
    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / "rec.json")
        try:
            subprocess.run([sys.executable, "-c", RECORDER, "90.0", str(seconds), out], env=env, timeout=180,
                           check=True)
            return _analyse(out, rate)
        finally:
            stop_processes(procs, sig=signal.SIGTERM)


def loops() -> str:
    ctl = [str(BIN / "hyst_controller_node"), "--ros-args", "-p", "rate:=1000.0", "-p", "reference:=sine:5",
           "-p", "state_decimation:=100"]
    a = _loop([[sys.executable, "-c", SIM, "--ros-args", "-p", "rate:=1000.0"], ctl], 1000.0)
    b = _loop([[str(BIN / "hyst_loop_node"), "--ros-args", "-p", "rate:=2000.0", "-p", "frequency:=5.0"]], 2000.0)
    lines = ["| loop | target (Hz) | achieved state rate (Hz) | round trip p50 / p99 (ms) | missed periods / 5 s | "
             "unanswered states |", "|---|---|---|---|---|---|"]
    notes = []
    cores = os.cpu_count() or 1
    for name, tgt, m in (("sim + controller, 2 processes", 1000, a), ("hyst_loop_node, 1 process", 2000, b)):
        lines.append(f"| {name} | {tgt} | {m['rate']:.0f} | {m['p50']:.2f} / {m['p99']:.2f} | {m['missed']:.0f} | "
                     f"{m['unanswered']} |")
        if "note" in m:
            notes.append(f"- {name}: {m['note']}")
            continue
        notes.append(f"- {name}: up and answering after {m['up']:.1f} s")
        if m["missed"] > 0.1 * tgt * 5.0 or os.getloadavg()[0] > cores:
            notes.append(f"- {name}: NOT TRUSTWORTHY as a figure of the code: {m['missed']:.0f} missed periods, load "
                         f"{os.getloadavg()[0]:.1f} on {cores} cores (the machine, not the loop, sets this figure)")
    return "\n".join(lines + [""] + notes)


def main() -> str:
    load = os.getloadavg()
    return "\n\n".join([f"Machine load average (1/5/15 min): {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} on "
                        f"{os.cpu_count()} cores", step_cost(), loops()])


if __name__ == "__main__":
    print(main())
