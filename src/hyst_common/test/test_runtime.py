"""hyst_common.runtime: real-time scheduling for the loop nodes, and what happens when it is not allowed."""
import os
import subprocess
import sys

import pytest

from hyst_common import runtime
from hyst_common.runtime import RT_PRIORITY_MAX, set_realtime, stop_processes


def test_zero_keeps_normal_scheduling_and_bad_values_are_one_error():
    s = set_realtime(0)
    assert s.policy == "normal" and s.priority == 0 and str(s) == "normal (rt_priority 0)"
    for bad in (-1, RT_PRIORITY_MAX + 1, 99):
        with pytest.raises(ValueError, match="rt_priority must be 0"):
            set_realtime(bad)


def test_refused_permission_is_reported_not_raised(monkeypatch):
    def refuse(*_):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    s = set_realtime(30)
    assert s.policy == "normal" and "refused" in s.note and "CAP_SYS_NICE" in str(s)


def test_every_thread_of_the_process_gets_fifo_where_allowed():
    """In a child process (the test process keeps its scheduling): threads started before the call (like the
    middleware's receive threads) and after it both end up SCHED_FIFO at the priority."""
    code = """
import os, threading, time
from hyst_common.runtime import set_realtime
ev = threading.Event(); up = threading.Event(); seen = {}
def early():
    seen['early'] = threading.get_native_id(); up.set(); ev.wait()
t = threading.Thread(target=early); t.start(); assert up.wait(60)
s = set_realtime(17)
def late():
    seen['late'] = (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
t2 = threading.Thread(target=late); t2.start(); t2.join()
pol_early = (os.sched_getscheduler(seen['early']), os.sched_getparam(seen['early']).sched_priority)
ev.set(); t.join()
print(s.policy, pol_early == (os.SCHED_FIFO, 17), seen['late'] == (os.SCHED_FIFO, 17))
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    policy, early, late = out.stdout.split()
    if policy != "fifo":
        pytest.skip("this machine does not allow SCHED_FIFO (needs CAP_SYS_NICE or an rtprio limit)")
    assert early == "True" and late == "True"


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="thread ids come from Linux /proc")
def test_thread_list_is_this_process():
    import threading
    ids = runtime._threads()
    assert os.getpid() in ids and threading.get_native_id() in ids
    seen, started, stop = [], threading.Event(), threading.Event()
    th = threading.Thread(target=lambda: (seen.append(threading.get_native_id()), started.set(), stop.wait(60)))
    th.start()
    try:
        assert started.wait(60)
        assert seen[0] in runtime._threads()
    finally:
        stop.set()
        th.join()


def test_own_args_are_those_before_ros_args():
    from hyst_common.runtime import own_args
    assert own_args(["-h", "--ros-args", "-p", "a:=1"]) == ["-h"]
    assert own_args(["--ros-args", "--help"]) == []


def test_stop_processes_signals_then_kills_what_ignores_the_signal():
    # the handler set explicitly: a child of a background job inherits SIGINT ignored (make test-stress)
    polite = subprocess.Popen([sys.executable, "-c", "import signal, time\nsignal.signal(signal.SIGINT, "
                               "signal.default_int_handler)\nprint('up', flush=True)\ntime.sleep(600)"],
                              stdout=subprocess.PIPE, text=True)
    stubborn = subprocess.Popen([sys.executable, "-c", "import signal, time\nsignal.signal(signal.SIGINT, "
                                 "signal.SIG_IGN)\nprint('up', flush=True)\ntime.sleep(600)"],
                                stdout=subprocess.PIPE, text=True)
    assert polite.stdout.readline().strip() == "up" and stubborn.stdout.readline().strip() == "up"
    # generous grace for the one that stops (a loaded host took > 2 s); the other ignores SIGINT, so it is killed
    # whatever the grace: nothing here depends on how fast the machine is
    assert stop_processes([polite], grace=120.0) == [-2]  # SIGINT reached it (Python exits by the signal)
    assert stop_processes([stubborn], grace=0.5) == [-9]  # ignored SIGINT: killed after the grace time
    assert polite.poll() is not None and stubborn.poll() is not None
    polite.stdout.close()
    stubborn.stdout.close()
