"""hyst_emulator: a fake amplifier + displacement sensor on a pty pair, driven by an injected stage plant.

For tests and for users without hardware::

    hyst_emulator --profile pea --rate 1000            # prints the port path, serves until Ctrl-C
    hyst_driver_node --ros-args -p port:=/tmp/hyst_emulator_XXXX/tty

It speaks both protocols at once (a line starting with ``$`` is HDB/1, anything else GCS-like), steps the plant it
is given once per sample with the voltage last set (the console script ``hyst_emulator``, :mod:`hyst_bringup.emulator`,
gives it the sim's ``hyst_sim.plant.Plant``: the driver package does not depend on the sim), and can inject every
fault the driver must survive: ``garbage`` bytes, ``partial`` lines, ``checksum`` corruption, ``timeout`` (silence),
device ``error`` replies, and ``unplug`` (the port vanishes and comes back at the same path, like a USB device
behind a ``/dev/serial/by-id`` link: the path is a symlink re-pointed at a fresh pty). The device itself (frames
in, frames out, the plant stepped) is :mod:`.emulated_device`; this module is the pty, the faults and the CLI.
"""
from __future__ import annotations

import argparse
import os
import random
import select
import signal
import sys
import tempfile
import threading
import time
import tty

from hyst_common.argtypes import nonneg_int
from hyst_common.runtime import set_realtime
from hyst_common.startup import end_quiet_start

from . import protocol_ascii as hdb
from . import protocol_gcs as gcs
from .emulated_device import FAULTS, EmulatedDevice, FaultRates

__all__ = ["EmulatedDevice", "PtyEmulator", "FaultRates", "FAULTS", "main"]


def _is_pty_link(path: str) -> bool:
    """A symlink to a pseudo-terminal (what an emulator's port link is), not a user's file."""
    return os.path.islink(path) and os.readlink(path).startswith(("/dev/pts/", "/dev/tty"))


class PtyEmulator:
    """Serve an :class:`EmulatedDevice` on a pty pair from a background thread, injecting faults on request.

    Parameters
    ----------
    device : EmulatedDevice
    link : str, optional
        Stable path (symlink to the current pty); default a fresh temporary directory's ``tty``.
    rates : FaultRates
        Random faults (CLI); tests use :meth:`inject` instead.
    timeout_s, unplug_s : float
        Duration of a ``timeout`` silence and of an ``unplug``.
    """

    def __init__(self, device: EmulatedDevice, link: str | None = None, rates: FaultRates | None = None,
                 seed: int = 0, timeout_s: float = 0.1, unplug_s: float = 0.1) -> None:
        self.device = device
        self._tmpdir: str | None = None
        if link:
            if os.path.lexists(link) and not _is_pty_link(link):
                # a stale link of an emulator that died is replaced; anything else is the user's
                raise FileExistsError(f"{link} exists and is not an emulator's port link; give another path")
            self.link = link
        else:
            self._tmpdir = tempfile.mkdtemp(prefix="hyst_emulator_")
            self.link = os.path.join(self._tmpdir, "tty")
        self.rates = rates or FaultRates()
        self.rng = random.Random(seed)
        self.timeout_s, self.unplug_s = timeout_s, unplug_s
        self.dt = device.plant.config.dt
        self.injected = {k: 0 for k in FAULTS}
        self.overruns = 0
        #: Device sample number when the last fault went on the wire (HDB/1 ``seq``): a host that has read a
        #: sample two later has read the fault too (the link is FIFO), so tests wait for that, not for a time.
        self.fault_seq = -1
        self._queue: list[tuple[str, float, float | None]] = []
        #: Index into ``device.applied`` of the first sample after the last power-up reset (``inject(...,
        #: reset_v=...)``): the jump to the reset voltage is the device's own, not the driver's.
        self.reset_at = -1
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._master = self._slave = -1
        self._silent_until = 0.0
        self._partial_next = self._corrupt_next = False
        self.pty_name = ""

    # ------------------------------------------------------------ pty
    def _plug(self) -> None:
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no CR/LF translation, before anyone opens it
        os.set_blocking(self._master, False)
        self.pty_name = os.ttyname(self._slave)
        tmp = f"{self.link}.{os.getpid()}.new"  # ours alone: a user's LINK.new stays untouched
        if os.path.lexists(tmp) and _is_pty_link(tmp):
            os.unlink(tmp)
        os.symlink(self.pty_name, tmp)
        os.replace(tmp, self.link)  # atomic: the path never points at a dead pty

    def _unplug(self) -> None:
        if os.path.islink(self.link) and os.readlink(self.link) == self.pty_name:  # only the link we made
            os.unlink(self.link)
        for fd in (self._master, self._slave):
            if fd >= 0:
                os.close(fd)
        self._master = self._slave = -1

    # ------------------------------------------------------------ control
    def start(self) -> "PtyEmulator":
        self._plug()
        self._thread = threading.Thread(target=self._loop, name="hyst_emulator", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        self._unplug()
        if self._tmpdir is not None:
            try:
                os.rmdir(self._tmpdir)
            except OSError:
                pass

    def inject(self, kind: str, duration: float | None = None, reset_v: float | None = None) -> None:
        """Queue one fault (thread-safe); ``duration`` for ``timeout``/``unplug`` (s); ``reset_v`` (V, ``unplug``
        only): the amplifier powers up at this voltage when plugged back in (reset in the emulator's own thread,
        so it cannot race a sample)."""
        if kind not in FAULTS:
            raise ValueError(f"unknown fault {kind!r}")
        with self._lock:
            self._queue.append((kind, duration if duration is not None else
                                (self.unplug_s if kind == "unplug" else self.timeout_s), reset_v))

    def __enter__(self) -> "PtyEmulator":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------ loop
    def _send(self, data: bytes) -> None:
        if not data or self._master < 0 or time.monotonic() < self._silent_until:
            return
        if self._corrupt_next:
            self._corrupt_next = False
            i = self.rng.randrange(1, max(2, len(data) - 2))
            data = data[:i] + bytes([(data[i] ^ (1 << self.rng.randrange(7))) or 0x41]) + data[i + 1:]
        if self._partial_next:
            self._partial_next = False
            data = data[:self.rng.randrange(1, max(2, len(data) - 1))]  # no line end: splices with the next
        try:
            os.write(self._master, data)
        except (BlockingIOError, OSError):
            pass  # nobody reads (host disconnected, buffer full): a real device drops it too

    def _apply(self, kind: str, duration: float, reset_v: float | None = None) -> None:
        self.fault_seq = self.device.seq
        self.injected[kind] += 1
        if kind == "garbage":
            n = self.rng.randrange(1, 64)
            self._send(bytes(self.rng.randrange(256) for _ in range(n)))
        elif kind == "partial":
            self._partial_next = True
        elif kind == "checksum":
            self._corrupt_next = True
        elif kind == "timeout":
            self._silent_until = time.monotonic() + duration
        elif kind == "error":
            self.device.gcs_error = 1000
            self._send(hdb.encode_error(5))
        elif kind == "unplug":
            self._unplug()
            self._stop.wait(duration)
            if reset_v is not None:  # powered up again at reset_v, before the host can see the port
                self.device.v_set = reset_v
                self.device.plant.reset(reset_v)
                self.reset_at = len(self.device.applied)
            if not self._stop.is_set():
                self._plug()

    def _random_faults(self) -> None:
        r = self.rates
        for kind in FAULTS:
            p = getattr(r, kind)
            if p and self.rng.random() < p:
                self._apply(kind, self.unplug_s if kind == "unplug" else self.timeout_s)

    def _loop(self) -> None:
        framer = hdb.LineFramer(max(hdb.MAX_FRAME, gcs.MAX_LINE))
        next_tick = time.monotonic() + self.dt
        while not self._stop.is_set():
            with self._lock:
                queued, self._queue = self._queue, []
            for kind, duration, reset_v in queued:
                self._apply(kind, duration, reset_v)
            now = time.monotonic()
            timeout = max(0.0, next_tick - now)
            try:
                ready, _, _ = select.select([self._master], [], [], timeout) if self._master >= 0 else ([], [], [])
            except (OSError, ValueError):
                ready = []
            if ready:
                try:
                    data = os.read(self._master, 4096)
                except (BlockingIOError, OSError):
                    data = b""
                for line in framer.feed(data):
                    self._send(self.device.handle(line))
            if self._master < 0:
                self._stop.wait(timeout)
            now = time.monotonic()
            if now >= next_tick:
                self._random_faults()
                self._send(self.device.tick())
                next_tick += self.dt
                behind = int((now - next_tick) / self.dt)
                if behind > 20:  # fell far behind (loaded machine): the clock and the stage go on, samples are lost
                    self.overruns += 1
                    for _ in range(behind):
                        self.device.tick(emit=False)
                    next_tick += behind * self.dt


def _parse(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="hyst_emulator", description=__doc__.split("\n\n")[0])
    ap.add_argument("--profile", default="pea", choices=("pea", "gma", "custom"),
                    help="actuator profile (default pea); custom: another stage, with --params-file (its model), "
                         "--v-min and --v-max (its amplifier's range, V)")
    ap.add_argument("--v-min", type=float, default=None, help="profile custom: lowest voltage the stage takes, V")
    ap.add_argument("--v-max", type=float, default=None, help="profile custom: highest voltage the stage takes, V")
    ap.add_argument("--rate", type=float, default=1000.0, help="sample rate, Hz (default 1000)")
    ap.add_argument("--link", default=None, help="stable port path to create (symlink to the pty)")
    ap.add_argument("--scenario", default=None, help="hidden-effects scenario file for the plant")
    ap.add_argument("--params-file", default=None, help="MBW params file for the plant")
    ap.add_argument("--faults", default="", help="random faults per line, e.g. garbage=0.001,unplug=1e-5")
    ap.add_argument("--seed", type=nonneg_int, default=0)
    ap.add_argument("--nice", type=int, default=0,
                    help="change the scheduling priority (negative = higher; needs privileges): a real DAQ bridge "
                         "has its own microcontroller and never waits for a busy host")
    ap.add_argument("--rt-priority", type=int, default=0,
                    help="SCHED_FIFO priority 1-98 for the emulated device (0 = normal scheduling; needs "
                         "CAP_SYS_NICE): as --nice, but the host's load cannot delay a tick at all")
    return ap.parse_args(argv)


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def main(argv: list[str] | None = None, *, build=None) -> int:
    """The ``hyst_emulator`` command around an injected device factory.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (``sys.argv[1:]`` if omitted).
    build : callable, optional
        ``build(profile, rate, scenario, params_file, seed, v_range) -> EmulatedDevice`` (``v_range``: the
        ``(v_min, v_max)`` given, or None); by default a linear stage
        (:func:`hyst_driver.linear_stage.linear_device`: the driver alone, no simulator); the console script
        ``hyst_emulator`` (:func:`hyst_bringup.emulator.main`) passes one on the sim's plant.
    """
    end_quiet_start()  # Ctrl-C from here: KeyboardInterrupt, which stops the emulator cleanly
    if build is None:
        from .linear_stage import linear_device as build
    args = _parse(argv)
    try:
        rates = FaultRates.parse(args.faults)
        if (args.v_min is not None or args.v_max is not None) and args.profile != "custom":
            raise ValueError("--v-min and --v-max set the range of a custom stage (--profile custom); the pea and "
                             "gma profiles have their amplifiers' ranges")
        v_range = None if args.v_min is None and args.v_max is None else (args.v_min, args.v_max)
        dev = build(args.profile, args.rate, args.scenario, args.params_file, args.seed, v_range)
    except (ValueError, OSError) as err:
        print(f"hyst_emulator: {err}", file=sys.stderr)
        return 2
    except Exception as err:  # hyst errors (bad scenario/params file): one line, no traceback
        if type(err).__module__.startswith("hyst_"):
            print(f"hyst_emulator: {err}", file=sys.stderr)
            return 2
        raise
    if args.nice:
        try:
            os.nice(args.nice)
        except OSError as err:
            print(f"hyst_emulator: priority unchanged ({err}); timing follows the host's load", file=sys.stderr)
    try:
        sched = set_realtime(args.rt_priority)
    except ValueError as err:
        print(f"hyst_emulator: {err}", file=sys.stderr)
        return 2
    if args.rt_priority and sched.policy != "fifo":
        print(f"hyst_emulator: {sched.note}; timing follows the host's load", file=sys.stderr)
    signal.signal(signal.SIGTERM, _raise_interrupt)  # `kill` cleans up the port link like Ctrl-C
    try:
        emu = PtyEmulator(dev, args.link, rates, seed=args.seed)
    except FileExistsError as err:
        print(f"hyst_emulator: --link {err}", file=sys.stderr)
        return 2
    try:
        emu.start()
    except OSError as err:
        print(f"hyst_emulator: cannot create the port at {emu.link}: {err}", file=sys.stderr)
        return 2
    print(f"hyst_emulator: {args.profile} stage at {args.rate:g} Hz on {emu.link} (pty {emu.pty_name}); "
          f"protocols ascii (HDB/1) and gcs", flush=True)
    rng = f" -p v_min:={args.v_min!r} -p v_max:={args.v_max!r}" if args.profile == "custom" else ""
    print(f"  hyst_driver_node --ros-args -p port:={emu.link} -p profile:={args.profile}{rng}", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        emu.stop()
        print(f"hyst_emulator: stopped; faults injected {emu.injected}", flush=True)
    return 0
