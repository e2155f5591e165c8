"""``hyst demo``: the closed loop on the embedded default stage, a bag under ``bags/``, a tracking summary.

Runs ``hyst_loop_node`` (simulated stage + reference + controller in one process at 2 kHz) through a schedule
of algorithms (default DPPC, DMRAC, PID, 2 s each, on a 5 Hz, 10 µm sine about 15 µm; ``--profile gma``: the GMA's
embedded stage, the sine placed on its rest stroke as on the PEA's, ±6.7 µm about 0) while ``hyst_bag_record``
records ``/stage/state``, ``/stage/command``, ``/stage/reference`` and ``/controller/state``. Prints RMSE/MAE per
algorithm (from the controller node's own statistics) and the bag path; exits non-zero when the loop did not run.
Executables are found next to the Python interpreter (venv) or, in a colcon install, under
``get_package_prefix(pkg)/lib/pkg``.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from hyst_common.profiles import get_profile
from hyst_common.runtime import stop_processes
from hyst_control.controllers import parse_schedule
from hyst_control.errors import LoopError
from hyst_control.reference import parse_reference
from hyst_model.core import stage_model
from hyst_sim.bagio import default_bag_path

from .loop import warm_up

__all__ = ["register", "run", "find_executable", "timing_note"]

#: Share of missed real-time periods above which the summary says the figures are the machine's.
LATE_SHARE_NOTE = 0.05


def find_executable(name: str, pkg: str) -> str:
    """Path of a console script: next to ``sys.executable``, in ``<prefix>/lib/<pkg>``, or on PATH."""
    here = Path(sys.executable).parent / name
    if here.exists():
        return str(here)
    try:
        from ament_index_python.packages import get_package_prefix
        cand = Path(get_package_prefix(pkg)) / "lib" / pkg / name
        if cand.exists():
            return str(cand)
    except Exception:  # noqa: BLE001 - not a colcon install
        pass
    found = shutil.which(name)
    if found:
        return found
    raise LoopError(f"cannot find the executable {name!r} (package {pkg}); run `make setup` or source the install")


def register(subparsers) -> None:
    """Add the ``demo`` subcommand to the ``hyst`` dispatcher."""
    p = subparsers.add_parser("demo", help="closed loop on the simulated stage, record a bag, print a summary",
                              description=__doc__.split("\n\n")[0])
    p.add_argument("--schedule", default="dppc:2,dmrac:2,pid:2", help="ALG:SECONDS,... (default %(default)s)")
    p.add_argument("--profile", choices=("pea", "gma"), default="pea",
                   help="embedded stage: pea (0-150 V, 30 um; default) or gma (+-5 V, +-20 um)")
    p.add_argument("--rate", type=float, default=2000.0, help="loop rate (Hz), default 2000")
    p.add_argument("--frequency", type=float, default=5.0, help="sine frequency (Hz), default 5")
    p.add_argument("--bags", type=Path, default=Path("bags"), help="directory for the bag (default bags/)")
    p.add_argument("--rt-priority", type=int, default=40,
                   help="SCHED_FIFO priority of the loop's threads, 0 = normal scheduling (default %(default)s; "
                        "without permission the loop warns and runs normally)")
    p.add_argument("--lockstep", action="store_true",
                   help="deterministic: the sim steps once per command and the controller generates the sine")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    schedule = parse_schedule(args.schedule)
    if not schedule:
        raise LoopError("empty schedule")
    seconds = sum(d for _, d in schedule)
    if seconds > 40:
        raise LoopError("the demo schedule must total at most 40 s")
    if not (0 < args.frequency <= 100 and 100 <= args.rate <= 2000):
        raise LoopError("--frequency must be in (0, 100] Hz and --rate in [100, 2000] Hz")
    if not 0 <= args.rt_priority <= 98:
        raise LoopError("--rt-priority must be 0 (normal scheduling) or 1-98")
    try:
        args.bags.mkdir(parents=True, exist_ok=True)
    except OSError as bad:  # a file of that name, a path under a file or /proc: one line, not a traceback
        raise LoopError(f"--bags {args.bags}: cannot use it as the bag directory ({bad.strerror or bad})") from None
    bag = default_bag_path(args.bags, "demo")
    warm_up([a for a, _ in schedule], args.rate)  # compile before the timed loop (first run after setup)
    env = dict(os.environ)
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    ros = ["--ros-args", "-p", f"rate:={args.rate}", "-p", "shape:=sine", "-p", f"frequency:={args.frequency}",
           # real-time scheduling as on a rig (hyst_common.runtime): with it PID's worst error in this demo fell
           # from 10-14 µm to 0.5-0.7 µm in most runs on the test machine (one run of five: 8.7 µm)
           "-p", f"hyst_sim:rt_priority:={args.rt_priority}", "-p", f"hyst_controller:rt_priority:={args.rt_priority}",
           "-p", f"hyst_sim:profile:={args.profile}", "-p", f"hyst_controller:profile:={args.profile}"]
    if args.profile != "pea":  # the sine sits on this stage's rest stroke as it sits on the PEA's (the controller
        m, lim = stage_model(args.profile), get_profile(args.profile)  # places its own spec alike, lockstep)
        ref = parse_reference(f"sine:{args.frequency}", stroke=m.rest_range(lim.v_min, lim.v_max))
        ros += ["-p", f"hyst_reference:offset:={ref.offset!r}", "-p", f"hyst_reference:amplitude:={ref.amplitude!r}"]
    if args.lockstep:
        ros += ["-p", "hyst_sim:mode:=lockstep", "-p", f"hyst_controller:reference:=sine:{args.frequency}",
                "-p", "hyst_controller:watchdog_periods:=1000000"]  # lockstep may pause; the stage is not lost
    rec = subprocess.Popen([find_executable("hyst_bag_record", "hyst_sim"), "-o", str(bag)], env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    loop = subprocess.Popen([find_executable("hyst_loop_node", "hyst_bringup"), "--schedule", args.schedule,
                             "--summary-json", "--wait-subscribers", "2", *ros], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    print(f"hyst demo: {', '.join(f'{a} {d:g} s' for a, d in schedule)} at {args.rate:g} Hz on a "
          f"{args.frequency:g} Hz sine, {args.profile.upper()} stage; recording {bag}", flush=True)
    try:
        # a segment may stretch (composed.SEGMENT_STRETCH); lockstep counts the stage's time, however slow
        out, err = loop.communicate(timeout=(20 if args.lockstep else 3) * seconds + 30)
    except subprocess.TimeoutExpired:
        stop_processes([loop, rec])
        raise LoopError("the closed loop did not finish in time") from None
    finally:
        time.sleep(0.3)
        stop_processes([rec])
    summary = None
    for line in out.splitlines()[::-1]:
        if line.startswith("{"):
            summary = json.loads(line)
            break
    if loop.returncode != 0 or summary is None:
        raise LoopError(f"hyst_loop_node failed (exit {loop.returncode}): {err.strip().splitlines()[-1:] or ''}")
    tracking = summary["tracking"]
    ran = [a for a, _ in schedule if tracking.get(a, {}).get("samples", 0) > 0]
    print(f"{'algorithm':<10} {'samples':>8} {'RMSE (um)':>10} {'MAE (um)':>10}")
    for a, _ in schedule:
        m = tracking.get(a, {"samples": 0, "rmse": float("nan"), "mae": float("nan")})
        print(f"{a:<10} {m['samples']:>8d} {m['rmse'] * 1e6:>10.4f} {m['mae'] * 1e6:>10.4f}")
    sim = summary.get("sim", {})
    print(f"loop: {summary['controller']['commands']} commands in {summary['seconds']:.1f} s; sim samples "
          f"{sim.get('samples', 0)}, late ticks {sim.get('late_ticks', 0)}; bag: {bag}")
    note = timing_note(int(sim.get("samples", 0)), int(sim.get("late_ticks", 0)), args.rate)
    if note:
        print(note)
    rec_out = rec.stdout.read() if rec.stdout else ""
    if not bag.exists():
        raise LoopError(f"no bag was written ({rec_out.strip()})")
    if len(ran) != len(schedule):
        raise LoopError(f"the loop did not run every algorithm (ran: {', '.join(ran) or 'none'})")
    return 0


def timing_note(samples: int, late: int, rate: float) -> str | None:
    """A sentence when the real-time loop missed more than :data:`LATE_SHARE_NOTE` of its periods, else None."""
    total = samples + late
    if total <= 0 or late <= LATE_SHARE_NOTE * total:
        return None
    return (f"note: this machine missed {100 * late / total:.0f} % of the {rate:g} Hz periods (the stage ran on at "
            "the held voltage, unmeasured), so the figures above are the machine's; `hyst demo --lockstep` gives "
            "the code's")
