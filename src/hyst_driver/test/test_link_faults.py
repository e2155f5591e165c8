"""Fault injection at the link level: each fault class 100 times, over a real pty, through a DeviceLink.

After every injected fault the link must be running and delivering samples again, the fault must show in the
health counters, and no voltage outside the limits (or faster than the slew limit) may ever reach the device —
while the command stream itself is hostile (NaN, ±inf, 1e300, values far outside the window). The judge of
the limits is the voltage the emulated amplifier applied at each of its samples.

Nothing here waits a fixed time and then asserts: every wait is for an event (the emulator put the fault on the
wire, the host read past it, a counter moved) with a generous deadline, so a loaded machine (load ≈ 9) only
makes the tests slower. What a stalled host legitimately causes (a timeout, a reconnect) is tolerated up to 10 %.
"""
from __future__ import annotations

import pytest

from hyst_driver.adapter import PROTOCOLS

RUNS = 100


#: Deadline (s) of every wait: generous, a deadline only decides when a hung test gives up.
DEADLINE = 30.0  # generous: only a failing run waits it out (10 s ran out at load 20)


def _recovered(rig, after_samples: int) -> bool:
    h = rig.link.health
    return rig.run_until(lambda: h.state == "running" and h.samples >= after_samples + 3, DEADLINE)


def _frame_faults(rig, fault: str) -> int:
    """Inject ``fault`` RUNS times, each read past and recovered from; return how many the health counters saw."""
    assert rig.run_until(lambda: rig.link.health.state == "running", DEADLINE), rig.link.health
    h = rig.link.health
    noticed = 0
    for i in range(RUNS):
        before = (sum(h.bad_frames.values()), h.device_errors, h.lost_samples, h.samples)
        rig.emu.inject(fault)
        assert rig.fault_read(i + 1, DEADLINE), f"run {i}: fault not read: {rig.link.snapshot()}"
        assert _recovered(rig, before[3]), f"run {i}: {rig.link.snapshot()}"
        after = (sum(h.bad_frames.values()), h.device_errors, h.lost_samples)
        noticed += after != before[:3]
        if fault == "error":  # device errors are reported every time, whichever protocol (GCS: via ERR?)
            assert rig.run_until(lambda: h.device_errors > before[1], DEADLINE), \
                f"run {i}: device error not reported"
    assert rig.emu.injected[fault] == RUNS
    # A frame fault must not cost the connection; a loaded host stalling this process for longer than
    # link_timeout may, rarely — a driver that reconnects on bad frames would show ~RUNS here.
    assert h.disconnects <= 0.1 * RUNS, f"{fault} costs the connection: {rig.link.snapshot()}"
    # nor a sample timeout (GCS resynchronising after garbage once waited one out per burst: 90 of 100); a host
    # stall may cost one now and then
    assert h.timeouts <= 0.5 * RUNS, f"{fault} costs a sample timeout: {rig.link.snapshot()}"
    # Every read-back is a voltage the driver wrote. A reply paired with the wrong query (GCS has no ids: a
    # position in µm taken for the applied voltage) shows here first, and read twice in a row it re-seeds the
    # limiter: a 69.6 V step reached the device in CI. Uncounted pairing: 0-34 per 100 garbage faults by seed.
    assert rig.link.limiter.counts.unexplained <= 1, rig.link.limiter.counts
    return noticed


@pytest.mark.slow
@pytest.mark.parametrize("protocol", PROTOCOLS)
@pytest.mark.parametrize("fault", ["garbage", "partial", "checksum", "error"])
def test_frame_faults_100_runs(make_rig, check_received, check_applied, test_limits, protocol, fault):
    rig = make_rig(protocol, seed=sum(map(ord, protocol + fault)), link_timeout=0.5)  # loaded CI: no spurious drops
    noticed = _frame_faults(rig, fault)
    if protocol == "ascii" and fault != "garbage":
        # HDB/1 catches every corrupted or truncated frame (CRC-8, sequence numbers).
        assert noticed == RUNS, noticed
    elif fault != "checksum":
        # Noise made only of whitespace/line ends is harmless and ignored by design; without a checksum (GCS)
        # a corrupted digit can pass as a number, so only the checksum fault may go unnoticed there.
        assert noticed >= 0.9 * RUNS, noticed
    check_received(rig.device.received, test_limits)
    check_applied(rig.device, test_limits)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(4))
def test_gcs_garbage_never_shifts_the_reply_pairs(make_rig, check_received, check_applied, test_limits, seed):
    """Garbage spliced into GCS replies, on several seeds: where the old pairing went out of step (a late VOL?
    reply taken for the next POS?) depends on the bytes and the timing, so one seed is not enough."""
    rig = make_rig("gcs", seed=1000 + seed, link_timeout=0.5)
    _frame_faults(rig, "garbage")
    # the markers' replies resynchronise; they do not rename the device (a garbled one would)
    assert rig.link.health.identity.split(",")[1:2] == ["GCS-EMU"], rig.link.health.identity
    check_received(rig.device.received, test_limits)
    check_applied(rig.device, test_limits)


@pytest.mark.slow
@pytest.mark.parametrize("protocol", PROTOCOLS)
def test_timeouts_100_runs(make_rig, check_received, check_applied, test_limits, protocol):
    rig = make_rig(protocol, seed=7, link_timeout=0.25)
    assert rig.run_until(lambda: rig.link.health.state == "running", DEADLINE)
    h = rig.link.health
    short_drops = 0
    for i in range(RUNS):
        t0, d0 = h.timeouts, h.disconnects
        long = i % 10 == 9  # every tenth silence outlasts link_timeout (0.25 s): the link must reconnect
        rig.emu.inject("timeout", 0.35 if long else 0.04)
        assert rig.run_until(lambda: h.timeouts > t0, DEADLINE), f"run {i}: silence not reported"
        if long:
            assert rig.run_until(lambda: h.disconnects > d0, DEADLINE), \
                f"run {i}: no reconnect after a long silence"
        assert _recovered(rig, h.samples), f"run {i}: {rig.link.snapshot()}"
        short_drops += (not long) and h.disconnects > d0
    # Exact counts would test the host's scheduler: a stall of this process may add a timeout (123 for 100
    # silences at load 10) or a reconnect. A driver counting every missing sample would show ~40 per silence.
    # (short drops: 8 of 90 at load 14, a stalled host reads nothing for longer than link_timeout)
    assert h.timeouts <= 2 * RUNS and short_drops <= 0.1 * RUNS, (h.timeouts, short_drops)
    check_received(rig.device.received, test_limits)
    check_applied(rig.device, test_limits)


@pytest.mark.slow
@pytest.mark.parametrize("protocol, runs", [("ascii", RUNS), ("gcs", RUNS)])
def test_unplug_and_replug_100_runs(make_rig, check_received, check_applied, test_limits, protocol, runs):
    # link_timeout 0.5 s: a loaded host that reads nothing for 0.1 s must not count as an extra unplug
    rig = make_rig(protocol, seed=11, link_timeout=0.5)
    assert rig.run_until(lambda: rig.link.health.state == "running", DEADLINE)
    h = rig.link.health
    for i in range(runs):
        c0, d0 = h.connects, h.disconnects
        rig.emu.inject("unplug", 0.02)
        # the unplug happened (the link saw it) and the link is back: two events, in this order
        assert rig.run_until(lambda: h.disconnects > d0, DEADLINE), f"run {i}: unplug unnoticed: {rig.link.snapshot()}"
        assert rig.run_until(lambda: h.connects > c0 and h.state == "running", DEADLINE), \
            f"run {i}: no reconnect: {rig.link.snapshot()}"
        assert _recovered(rig, h.samples)
    assert rig.emu.injected["unplug"] == runs
    assert runs <= h.disconnects <= runs + 0.1 * runs, h.disconnects  # a stalled host may add a few (110 at load 14)
    check_received(rig.device.received, test_limits)
    check_applied(rig.device, test_limits)


def _running_at_110(make_rig, seed: int):
    """A rig whose amplifier applies 110 V. Commands keep coming until it does (a single command would let the
    0.05 s watchdog fire before a loaded host finished the ramp up: a test of the scheduler, not of the watchdog)."""
    rig = make_rig("ascii", seed=seed)
    assert rig.run_until(lambda: rig.link.health.state == "running", DEADLINE)

    def command_110() -> bool:
        rig.link.command(110.0)
        return rig.device.plant.u_applied == 110.0

    assert rig.run_until(command_110, DEADLINE, command=False)
    return rig


def test_watchdog_ramps_to_safe_when_commands_stop(make_rig, test_limits, check_received, check_applied):
    rig = _running_at_110(make_rig, seed=3)
    # then they stop: after command_timeout the output ramps 110 -> 20 V at the slew limit, then keepalive
    assert rig.run_until(lambda: rig.link.health.watchdog_active and rig.device.received[-1] == test_limits.v_safe
                         and rig.device.plant.u_applied == test_limits.v_safe, DEADLINE, command=False)
    check_received(rig.device.received, test_limits)
    check_applied(rig.device, test_limits)


def test_a_stream_of_refused_commands_is_no_sign_of_life_for_the_watchdog(make_rig, test_limits, check_received,
                                                                           check_applied):
    """NaN and 1e300 commands kept the watchdog fed: the output held 75 V for seconds of garbage instead of
    ramping to v_safe, while /diagnostics said 'running'."""
    rig = _running_at_110(make_rig, seed=4)
    r0 = rig.link.health.rejected

    def garbage() -> bool:  # commands keep arriving, none of them usable
        rig.link.command(float("nan"))
        rig.link.command(1e300)
        return (rig.link.health.watchdog_active and rig.device.plant.u_applied == test_limits.v_safe)

    assert rig.run_until(garbage, DEADLINE, command=False)
    assert rig.link.snapshot().rejected > r0
    check_received(rig.device.received, test_limits)
    check_applied(rig.device, test_limits)


def test_shutdown_ramp_and_replug_reseed(make_rig, test_limits, check_received, check_applied):
    rig = make_rig("gcs", seed=5, command_timeout=10.0)
    assert rig.run_until(lambda: rig.link.health.state == "running", DEADLINE, command=False)
    rig.link.command(120.0)
    assert rig.run_until(lambda: rig.device.plant.u_applied == 120.0, DEADLINE, command=False)
    # The amplifier resets to 0 V while unplugged: after the replug the driver must start from 0 V (the
    # device's read-back), not from the 120 V it last sent, and climb at the slew limit.
    # (reset by the emulator's own thread while unplugged: a reset from this thread raced a sample at load 14)
    rig.emu.inject("unplug", 0.05, reset_v=0.0)
    assert rig.run_until(lambda: rig.link.health.connects == 2, DEADLINE, command=False)
    a0 = rig.emu.reset_at  # the device's own 120 -> 0 V jump is not the driver's
    assert a0 >= 0
    n0 = len(rig.device.received)
    rig.link.command(120.0)
    assert rig.run_until(lambda: len(rig.device.received) > n0, DEADLINE, command=False)
    assert rig.device.received[n0] <= 10.0 + 20.0 + 1e-6  # limiter re-seeded at 0 V (clamped to v_min 10 V)
    assert rig.link.ramp_to_safe(5.0)
    # the emulator reads the last line in its own time
    assert rig.run_until(lambda: rig.device.received[-1] == test_limits.v_safe, DEADLINE, command=False)
    check_received(rig.device.received[n0:], test_limits)
    check_applied(rig.device, test_limits, start=a0)


def test_commands_after_the_shutdown_ramp_began_are_never_written(make_rig, test_limits):
    """The node's executor may deliver a queued command while the main thread ramps down: it must not land."""
    rig = make_rig("ascii", seed=4)
    assert rig.run_until(lambda: rig.link.health.state == "running", DEADLINE, command=False)
    assert rig.link.ramp_to_safe(5.0)
    n = len(rig.device.received)
    rig.link.command(84.0)
    assert rig.link.health.late_commands == 1 and rig.link.health.writes == rig.link.snapshot().writes
    assert rig.run_until(lambda: rig.device.received[-1] == test_limits.v_safe and len(rig.device.received) >= n,
                         DEADLINE, command=False)
    assert 84.0 not in rig.device.received[n:]


@pytest.mark.parametrize("protocol", ["ascii", "gcs"])
def test_shutdown_ramp_reports_success_only_once_the_device_applies_v_safe(make_rig, test_limits, protocol):
    """``ramp_to_safe`` True means the amplifier's read-back shows v_safe, not that the link was settled.

    Right after closing began, the limiter sat settled at the last command (80 V here); the former check took
    that for the end of the ramp and returned at once, leaving the device at 74 V and 51 V in two of 20 fault
    tests under load.
    """
    rig = make_rig(protocol, seed=8, command_timeout=10.0)
    assert rig.run_until(lambda: rig.link.health.state == "running", DEADLINE, command=False)
    rig.link.command(80.0)
    assert rig.run_until(lambda: rig.device.plant.u_applied == 80.0 and rig.link.limiter.settled, DEADLINE,
                         command=False)
    assert rig.link.ramp_to_safe(5.0)
    assert rig.link.health.applied_v == pytest.approx(test_limits.v_safe, abs=1e-3)
    assert rig.device.plant.u_applied == pytest.approx(test_limits.v_safe, abs=1e-3)


def test_a_fault_while_ramping_down_does_not_abort_the_ramp(make_rig, test_limits):
    """A line that made the adapter raise during shutdown ended the ramp with a traceback, the device at 150 V."""
    rig = make_rig("ascii", seed=9, command_timeout=10.0)
    assert rig.run_until(lambda: rig.link.health.state == "running", DEADLINE, command=False)
    rig.link.command(80.0)
    assert rig.run_until(lambda: rig.device.plant.u_applied == 80.0, DEADLINE, command=False)
    real, calls = rig.link.service, []

    def flaky():
        calls.append(1)
        if len(calls) <= 3:
            raise ValueError("a line the adapter could not take")
        return real()

    rig.link.service = flaky
    assert rig.link.ramp_to_safe(5.0)
    assert rig.link.health.ramp_errors == 3
    assert rig.device.plant.u_applied == pytest.approx(test_limits.v_safe, abs=1e-3)
