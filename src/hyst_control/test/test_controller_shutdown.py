"""Ctrl-C and SIGTERM stop hyst_controller_node cleanly: exit code 0, no traceback (a stop is not an error)."""
import signal
import subprocess
import sys
import time

import pytest

pytest.importorskip("rclpy")
pytestmark = pytest.mark.ros


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_stops_the_controller_without_a_traceback(sig):
    code = "import sys; from hyst_control.controller_node import main; sys.exit(main())"
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        out = []
        t_end = time.monotonic() + 60
        while time.monotonic() < t_end:
            line = p.stdout.readline()
            out.append(line)
            if "controller ready" in line or not line:
                break
        assert "controller ready" in out[-1], "".join(out)
        time.sleep(0.3)  # waiting in spin_once, where the signal used to surface as a pybind11 RuntimeError
        p.send_signal(sig)
        rest, _ = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            p.kill()
    text = "".join(out) + rest
    assert p.returncode == 0, text
    assert "Traceback" not in text and "RuntimeError" not in text, text
