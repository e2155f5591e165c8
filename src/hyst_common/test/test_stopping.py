"""The stop watchdog (:mod:`hyst_common.stopping`): a hang after a signal ends the process with a reason.

Each case runs a small script in its own interpreter (the watchdog ends processes), waits for its ready line
(a condition, not a time), signals it and reads its exit code and stderr.
"""
import signal
import subprocess
import sys

import pytest

GUARD = r'''
import signal, sys, threading, time
from hyst_common.stopping import StopGuard
before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)  # SIG_IGN under a background job
g = StopGuard("probe", grace=float(sys.argv[2]))
case = sys.argv[1]
g.phase("spin")
if case == "other_signal":        # a signal the node handles itself is not a stop: no limit is armed by it
    signal.signal(signal.SIGUSR2, lambda *_: None)
    signal.raise_signal(signal.SIGUSR2)
    time.sleep(3 * g.grace)
print("ready", flush=True)
if case == "stuck_spin":          # the loop never reads the flag: the main thread stays in a blocking call
    threading.Event().wait()
while not g.stopped:
    time.sleep(0.01)
g.phase("exit")
if case == "long_exit":           # on_exit's own work may take longer than the grace: no limit there
    time.sleep(3 * g.grace)
g.phase("teardown")
if case == "stuck_teardown":
    threading.Event().wait()
g.close()
assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before, "handlers not restored"
assert signal.set_wakeup_fd(-1) == -1, "wakeup fd not restored"
print("clean", flush=True)
'''

NODE_TEARDOWN_HANGS = r'''
import sys, threading
import rclpy
import hyst_common.stopping as stopping
from hyst_common.node import run_node
from rclpy.node import Node

stopping.GRACE_S = 1.0
rclpy.try_shutdown = lambda *a, **k: threading.Event().wait()   # a teardown that never returns

class Probe(Node):
    def __init__(self):
        super().__init__("probe_hang")
        print("probe up", flush=True)

def on_exit(node, by_signal):
    print(f"on_exit ran, by_signal={by_signal}", flush=True)

sys.exit(run_node(Probe, [sys.argv[0]], prog="probe_node", on_exit=on_exit))
'''


def _signalled(code: str, *argv: str, ready: str, signals: int = 1) -> tuple[int, str, str]:
    p = subprocess.Popen([sys.executable, "-c", code, *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    try:
        first = p.stdout.readline()
        assert first.strip() == ready, (first, p.stderr.read() if p.poll() is not None else "")
        for _ in range(signals):
            p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
            p.communicate()
    return p.returncode, first + out, err


def test_a_normal_stop_is_untouched_and_restores_the_handlers():
    code, out, err = _signalled(GUARD, "normal", "1.0", ready="ready")
    assert code == 0 and "clean" in out and err == "", err


def test_two_signals_at_once_do_not_deadlock_the_handler():
    code, out, err = _signalled(GUARD, "normal", "1.0", ready="ready", signals=2)
    assert code == 0 and "clean" in out and err == "", err


def test_another_handled_signal_arms_no_limit():
    code, out, err = _signalled(GUARD, "other_signal", "0.5", ready="ready")
    assert code == 0 and "clean" in out and err == "", err


def test_a_long_on_exit_is_not_cut_short():
    code, out, err = _signalled(GUARD, "long_exit", "0.5", ready="ready")
    assert code == 0 and "clean" in out and err == "", err


def test_a_loop_that_never_ends_is_ended_with_exit_1_and_the_stacks():
    code, out, err = _signalled(GUARD, "stuck_spin", "1.0", ready="ready")
    assert code == 1 and "clean" not in out
    assert "probe: stopping: the process did not leave its spin loop within 1 s" in err
    assert "most recent call first" in err  # the stacks, for a bug report


def test_a_hung_teardown_after_the_work_is_done_exits_0_with_a_reason():
    code, out, err = _signalled(GUARD, "stuck_teardown", "1.0", ready="ready")
    assert code == 0 and "clean" not in out
    assert "finished its work but the ROS teardown did not return within 1 s" in err


@pytest.mark.ros
def test_run_node_bounds_a_hanging_rclpy_teardown():
    """Through ``run_node``: ``on_exit`` runs, then the (made to hang) ``rclpy.try_shutdown`` is cut short."""
    pytest.importorskip("rclpy")
    code, out, err = _signalled(NODE_TEARDOWN_HANGS, ready="probe up")
    assert "on_exit ran, by_signal=True" in out, (out, err)
    assert code == 0 and "probe_node: stopping:" in err and "ROS teardown did not return" in err, err


def test_a_sigint_while_a_hyst_executable_is_still_importing_is_one_line_and_exit_0():
    """The first half second of a node is imports (numpy, numba, rclpy): a Ctrl-C there ended in a 50-line
    KeyboardInterrupt traceback and exit 130. The signal is sent by the process itself, once hyst_common is
    imported (no timing involved); a process that is not a hyst executable keeps Python's default."""
    import subprocess
    import sys

    # the child first takes Python's default SIGINT handling, as a foreground process has it (a job started in
    # the background, as CI may be, inherits SIGINT ignored)
    code = ("import sys, signal; signal.signal(signal.SIGINT, signal.default_int_handler); sys.argv[0] = {name!r}; "
            "import os, hyst_common, time; os.kill(os.getpid(), signal.SIGINT); time.sleep(30)")
    r = subprocess.run([sys.executable, "-c", code.format(name="/x/bin/hyst_controller_node")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and "interrupted while starting" in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = subprocess.run([sys.executable, "-c", code.format(name="my_script.py")], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode != 0 and "KeyboardInterrupt" in r.stderr  # someone else's program: Python's behaviour
