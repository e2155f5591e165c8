"""Transport (loop://, pty, backoff) and the emulator's protocol engine, byte for byte.

Waits are for conditions with generous deadlines (:data:`DEADLINE`), never a fixed time before an assertion."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest
import serial

from hyst_driver import protocol_ascii as hdb
from hyst_driver.emulator import EmulatedDevice, FaultRates, PtyEmulator
from hyst_driver.errors import LinkError
from hyst_driver.transport import SerialTransport
from hyst_driver.linear_stage import linear_device

#: Deadline (s) of every wait: only decides when a hung test gives up.
DEADLINE = 30.0  # generous: only a failing run waits it out (10 s ran out at load 20)


def _read_until(t: SerialTransport, pred, timeout: float = DEADLINE) -> bytes:
    """Read from ``t`` until ``pred(data)`` or the deadline; return everything read."""
    deadline, data = time.monotonic() + timeout, b""
    while not pred(data) and time.monotonic() < deadline:
        data += t.read()
        time.sleep(0.005)
    return data


def test_loop_url_round_trip():
    t = SerialTransport("loop://")
    assert t.try_open(0.0) and t.is_open and t.fileno() is None
    t.write(hdb.encode_identify())
    assert _read_until(t, lambda d: b"\n" in d) == b"$ID*3D\r\n"
    t.close()
    with pytest.raises(LinkError):
        t.read()


def test_open_failures_back_off_exponentially():
    calls = []

    def opener(url, **kw):
        calls.append(url)
        if len(calls) < 5:
            raise serial.SerialException("no such device")
        return serial.serial_for_url("loop://", **kw)

    t = SerialTransport("/dev/ttyNOPE", opener=opener, backoff=(0.1, 0.4))
    times = [0.0, 0.05, 0.1, 0.25, 0.3, 0.5, 0.85, 0.9]
    opened = [t.try_open(now) for now in times]
    # attempts at 0.0 (fail, wait 0.1), 0.1 (fail, 0.2), 0.3 (fail, 0.4), 0.85 (fail, 0.4), 1.25: 5th succeeds
    assert opened == [False] * 8 and len(calls) == 4
    assert "no such device" in t.last_error
    assert t.try_open(1.3) and len(calls) == 5


def test_vanished_pty_raises_link_error():
    with PtyEmulator(linear_device("pea", 1000.0)) as emu:
        t = SerialTransport(emu.link)
        assert t.try_open(0.0)
        emu.inject("unplug", 1.5)  # long: the checks while unplugged must not race the replug on a loaded host
        deadline = time.monotonic() + DEADLINE
        with pytest.raises(LinkError):
            while time.monotonic() < deadline:  # until the emulator has pulled the plug
                t.read()
                t.write(b"$RP*91\r\n")
                time.sleep(0.005)
        assert not t.is_open and not os.path.exists(emu.link)
        assert not SerialTransport(emu.link).try_open(0.0)  # the path is gone while unplugged
        deadline = time.monotonic() + DEADLINE
        while not os.path.exists(emu.link) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert os.path.exists(emu.link) and SerialTransport(emu.link).try_open(0.0)  # back at the same path


@pytest.fixture(scope="module")
def dev():
    return linear_device("pea", 1000.0)


def test_emulated_device_hdb_replies_byte_for_byte(dev):
    dev = EmulatedDevice(dev.plant)
    assert dev.handle(b"$ID*3D") == b"$ID,hyst,HDB-EMU,0001,1.0*10\r\n"
    assert dev.handle(b"$SV,75000000*A5") == b"" and dev.v_set == 75.0 and dev.received == [75.0]
    assert dev.handle(b"$SV,-2500000*B2") == hdb.encode_error(4) and dev.v_set == 75.0
    assert dev.handle(b"$SV,75000000*A6") == hdb.encode_error(1)
    assert dev.handle(b"$ST,1000*79") == b"$OK,ST,1000*83\r\n"
    s1, s2 = hdb.decode_reply(dev.tick()), hdb.decode_reply(dev.tick())
    assert s2.seq == s1.seq + 1 and s2.t_us - s1.t_us == 1000 and s2.uv == 75_000_000
    assert s2.counts == round(dev.y / 2e-9) and 10e-6 < s2.counts * 2e-9 < 20e-6  # 75 V: mid stroke
    assert dev.handle(b"$SP*84") == b"$OK,SP*D4\r\n" and dev.tick() == b""


def test_emulated_device_gcs_replies(dev):
    dev = EmulatedDevice(dev.plant)
    assert dev.handle(b"*IDN?") == b"hyst,GCS-EMU,0001,1.0\n"
    assert dev.handle(b"SVA 1 200.0") == b"" and dev.handle(b"ERR?") == b"17\n" and dev.handle(b"ERR?") == b"0\n"
    assert dev.handle(b"XYZ") == b"" and dev.handle(b"ERR?") == b"2\n"
    dev.handle(b"SVA 1 30.5")
    dev.tick()
    assert dev.handle(b"VOL? 1") == b"1=30.500000\n"
    assert dev.handle(b"POS? 1") == f"1={dev.y * 1e6:.4f}\n".encode()


def test_fault_rates_parse():
    assert FaultRates.parse("garbage=0.01, unplug=1e-5").unplug == 1e-5
    for bad in ("bogus=0.1", "garbage=2", "garbage=x"):
        with pytest.raises(ValueError):
            FaultRates.parse(bad)


def _emulator_cmd(*args):
    return [sys.executable, "-c", "import sys; from hyst_driver.emulator import main; sys.exit(main())", *args]


def test_cli_bad_input_is_one_line_and_exit_2():
    r = subprocess.run(_emulator_cmd("--faults", "bogus=1"), capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and r.stderr.strip().count("\n") == 0 and "unknown fault" in r.stderr


@pytest.mark.slow
def test_cli_prints_port_serves_and_cleans_up(tmp_path):
    link = tmp_path / "stage"
    p = subprocess.Popen(_emulator_cmd("--link", str(link), "--profile", "gma"), stdout=subprocess.PIPE, text=True)
    try:
        first = p.stdout.readline()
        assert str(link) in first and "gma" in first
        t = SerialTransport(str(link))
        assert t.try_open(0.0)
        t.write(b"$RP*91\r\n")
        data = _read_until(t, lambda d: b"\n" in d)
        assert hdb.decode_reply(data).uv == 0  # GMA rests at 0 V
        t.close()
    finally:
        p.send_signal(signal.SIGTERM)
        p.wait(10)
    assert p.returncode == 0 and not os.path.lexists(link)


def test_device_clock_maps_sample_times_despite_host_jitter():
    from hyst_driver.transport import DeviceClock

    import random
    rng = random.Random(0)
    c = DeviceClock(wrap=10.0)
    out = []
    for k in range(3000):              # 1 kHz device clock wrapping every 10 s, host 100 s later + jitter 0..5 ms
        dev = (k * 1e-3) % 10.0
        host = 100.0 + k * 1e-3 + 2e-4 + (rng.random() ** 4) * 5e-3
        out.append(c.map(dev, host))
    d = [b - a for a, b in zip(out, out[1:])]
    assert max(abs(x - 1e-3) for x in d[100:]) < 2e-5          # regular 1 ms stamps: 5 ms jitter -> < 20 us
    assert all(o <= 100.0 + k * 1e-3 + 2e-4 + 5e-3 for k, o in enumerate(out))  # never after the arrival
    assert abs(out[-1] - (100.0 + 2.999 + 2e-4)) < 5e-5         # offset converges to the minimum latency
    c2 = DeviceClock(wrap=4.0)
    assert c2.map(3.999, 10.0) < c2.map(0.001, 10.01) < 10.01   # unwraps


def test_device_clock_follows_a_device_that_lost_time():
    from hyst_driver.transport import DeviceClock

    c = DeviceClock(window=1.0)
    for k in range(1000):
        c.map(k * 1e-3, 50.0 + k * 1e-3 + 3e-4)
    # the device stalls for 0.3 s (its clock stops, the host's does not), then runs on
    stamps = [c.map((1000 + k) * 1e-3, 50.3 + (1000 + k) * 1e-3 + 3e-4) for k in range(2500)]
    assert stamps[0] < 50.0 + 1.0 + 3e-4 + 1e-9           # within the window the old offset still holds
    assert abs(stamps[-1] - (50.3 + 3.499 + 3e-4)) < 1e-9  # one window later the stamps are right again


def test_device_clock_is_settled_only_after_a_full_window_since_reset():
    """Late first arrivals (a busy host after a reconnect) make the first mapped times late by as much: the
    limiter may use them to forget writes only once a whole window has been mapped."""
    from hyst_driver.transport import DeviceClock

    c = DeviceClock(window=1.0)
    late = [c.map(k * 1e-3, 10.0 + k * 1e-3 + 0.3) for k in range(5)]  # all 0.3 s late: looks like no latency
    assert not c.settled and late[0] - 10.0 > 0.29                         # the mapping cannot know
    for k in range(5, 1001):
        c.map(k * 1e-3, 10.0 + k * 1e-3 + 1e-4)
    assert c.settled and abs(c.map(1.001, 11.0012) - (10.0 + 1.001 + 1e-4)) < 1e-9
    c.reset()
    assert not c.settled


def test_a_link_path_that_is_a_users_file_is_refused_and_nothing_is_deleted(tmp_path):
    """--link PATH replaced a user's file with its symlink, deleted PATH.new, and removed the link on exit."""
    mine = tmp_path / "notes.txt"
    mine.write_text("precious")
    (tmp_path / "notes.txt.new").write_text("also mine")
    with pytest.raises(FileExistsError, match="not an emulator's port link"):
        PtyEmulator(linear_device("pea", 1000.0), link=str(mine))
    link = tmp_path / "tty"
    (tmp_path / "tty.new").write_text("mine too")
    with PtyEmulator(linear_device("pea", 1000.0), link=str(link)) as emu:
        assert os.readlink(link) == emu.pty_name
    assert not os.path.lexists(link)  # the link it made is gone, the user's files are not
    assert mine.read_text() == "precious" and (tmp_path / "notes.txt.new").read_text() == "also mine"
    assert (tmp_path / "tty.new").read_text() == "mine too"
    os.symlink("/dev/pts/999", link)  # a stale link of an emulator that died is replaced
    with PtyEmulator(linear_device("pea", 1000.0), link=str(link)) as emu:
        assert os.readlink(link) == emu.pty_name
