"""hyst_emulator: a fake amplifier + displacement sensor on a pty pair, driven by an injected stage plant.

For tests and for users without hardware::

    hyst_emulator --profile pea --rate 1000            # prints the port path, serves until Ctrl-C
    hyst_driver_node --ros-args -p port:=/tmp/hyst_emulator_XXXX/tty

It speaks both protocols at once (a line starting with ``$`` is HDB/1, anything else GCS-like), steps the plant it
is given once per sample with the voltage last set (the console script ``hyst_emulator``, :mod:`hyst_bringup.emulator`,
gives it the sim's ``hyst_sim.plant.Plant``: the driver package does not depend on the sim), and can inject every
fault the driver must survive: ``garbage`` bytes, ``partial`` lines, ``checksum`` corruption, ``timeout`` (silence),
device ``error`` replies, and ``unplug`` (the port vanishes and comes back at the same path, like a USB device
behind a ``/dev/serial/by-id`` link: the path is a symlink re-pointed at a fresh pty).
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
from array import array
from dataclasses import dataclass

from hyst_common.runtime import set_realtime

from . import protocol_ascii as hdb
from . import protocol_gcs as gcs
from .errors import ProtocolError

__all__ = ["EmulatedDevice", "PtyEmulator", "FaultRates", "FAULTS", "main"]

#: Fault classes the emulator injects.
FAULTS = ("garbage", "partial", "checksum", "timeout", "error", "unplug")


class EmulatedDevice:
    """Protocol engine of the fake device (no I/O): lines in, reply bytes out; :meth:`tick` samples the plant.

    Parameters
    ----------
    plant : object
        Stage model, e.g. ``hyst_sim.plant.Plant`` (injected: this package does not import the sim). Used:
        ``config`` (``v_min``, ``v_max``, ``dt``), ``u_applied``, ``step(v)`` and ``reset(v)``; its own amplifier
        clip (profile range and slew) is the device-side clamp.
    counts_to_m : float
        Sensor resolution (m per count) for HDB/1 ``P`` samples.
    """

    IDENTITY = hdb.Identity("hyst", "HDB-EMU", "0001", "1.0")

    def __init__(self, plant, counts_to_m: float = 2e-9) -> None:
        self.plant = plant
        self.counts_to_m = counts_to_m
        cfg = plant.config
        self.v_range = (cfg.v_min, cfg.v_max)
        self.v_set = plant.u_applied
        self.streaming = False
        self.seq = 0
        self.t_us = 0
        self.y = 0.0
        self.gcs_error = 0
        #: Every voltage the host asked for, as received (V): what tests check against the driver limits.
        self.received: list[float] = []
        #: The voltage the amplifier applied when each of those arrived (V), and the index into ``received`` at
        #: each identify request (a (re)connection handshake): a reconnecting host re-seeds its slew limiter
        #: from the applied voltage, so across a handshake the step is judged from there.
        self.applied_at_receipt: list[float] = []
        self.identified_at: list[int] = []
        #: The voltage the amplifier applied at every device sample (V), in sample order: the judge of the slew
        #: and range limits (two commands delivered within one sample show here as one step, the one the stage
        #: feels; in ``received`` they look like two small ones). 8 bytes a sample: 3.6 MB per hour at 1 kHz.
        self.applied = array("d")
        self.bad_lines = 0
        self._tick_us = round(cfg.dt * 1e6)

    # ------------------------------------------------------------ samples
    def tick(self, emit: bool = True) -> bytes:
        """Advance one sample; return a ``P`` frame when streaming (and ``emit``), else nothing."""
        r = self.plant.step(self.v_set)
        self.y = r.y
        self.applied.append(r.u_applied)
        self.seq = (self.seq + 1) & 0xFFFF
        self.t_us = (self.t_us + self._tick_us) & 0xFFFFFFFF
        return self._sample() if self.streaming and emit else b""

    def _sample(self) -> bytes:
        return hdb.encode_sample(hdb.Sample(self.seq, self.t_us, round(self.y / self.counts_to_m),
                                            hdb.volts_to_uv(self.plant.u_applied)))

    # ------------------------------------------------------------ commands
    def handle(self, line: bytes) -> bytes:
        """One received line (without ``\\n``) → reply bytes."""
        if not line.strip():
            return b""
        return self._hdb(line) if line.lstrip().startswith(b"$") or b"$" in line else self._gcs(line)

    def _set(self, volts: float) -> bool:
        self.received.append(volts)
        self.applied_at_receipt.append(self.plant.u_applied)
        if not self.v_range[0] <= volts <= self.v_range[1]:
            return False
        self.v_set = volts
        return True

    def _hdb(self, line: bytes) -> bytes:
        try:
            cmd = hdb.decode_command(line)
        except ProtocolError as err:
            self.bad_lines += 1
            return hdb.encode_error(1 if "checksum" in str(err) else 2)
        if isinstance(cmd, hdb.SetVoltage):
            return b"" if self._set(hdb.uv_to_volts(cmd.uv)) else hdb.encode_error(4)
        if isinstance(cmd, hdb.Identify):
            self.identified_at.append(len(self.received))
            return hdb.encode_identity(self.IDENTITY)
        if isinstance(cmd, hdb.ReadPosition):
            return self._sample()
        if isinstance(cmd, hdb.StartStream):
            self.streaming = True
            return hdb.encode_ack("ST", str(cmd.rate_hz))
        self.streaming = False
        return hdb.encode_ack("SP")

    def _gcs(self, line: bytes) -> bytes:
        try:
            cmd = gcs.decode_command(line)
        except ProtocolError as err:
            self.bad_lines += 1
            self.gcs_error = err.args[1] if len(err.args) > 1 else 1
            return b""
        if isinstance(cmd, gcs.SetOpenLoop):
            if not self._set(cmd.volts):
                self.gcs_error = 17
            return b""
        if isinstance(cmd, gcs.PosQuery):
            return gcs.encode_axis_value(self.y * 1e6, 4)
        if isinstance(cmd, gcs.VolQuery):
            return gcs.encode_axis_value(self.plant.u_applied, 6)
        if isinstance(cmd, gcs.ErrQuery):
            code, self.gcs_error = self.gcs_error, 0
            return gcs.encode_error_code(code)
        if isinstance(cmd, gcs.Idn):
            self.identified_at.append(len(self.received))
            i = self.IDENTITY
            return gcs.encode_idn_reply(f"{i.vendor},GCS-EMU,{i.serial},{i.firmware}")
        return b""  # SVO 1 0: open loop is the only mode


@dataclass
class FaultRates:
    """Probability per outgoing line of each random fault (CLI ``--faults garbage=0.001,unplug=1e-5``)."""

    garbage: float = 0.0
    partial: float = 0.0
    checksum: float = 0.0
    timeout: float = 0.0
    error: float = 0.0
    unplug: float = 0.0

    @classmethod
    def parse(cls, text: str) -> "FaultRates":
        out = cls()
        for item in filter(None, (s.strip() for s in text.split(","))):
            name, _, val = item.partition("=")
            if name not in FAULTS:
                raise ValueError(f"unknown fault {name!r}; choose from {', '.join(FAULTS)}")
            p = float(val)
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"fault rate {name}={val} must be a probability in [0, 1]")
            setattr(out, name, p)
        return out


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
        self._tmpdir = None if link else tempfile.mkdtemp(prefix="hyst_emulator_")
        self.link = link or os.path.join(self._tmpdir, "tty")
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
        tmp = self.link + ".new"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(self.pty_name, tmp)
        os.replace(tmp, self.link)  # atomic: the path never points at a dead pty

    def _unplug(self) -> None:
        if os.path.lexists(self.link):
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
    ap.add_argument("--profile", default="pea", choices=("pea", "gma"), help="actuator profile (default pea)")
    ap.add_argument("--rate", type=float, default=1000.0, help="sample rate, Hz (default 1000)")
    ap.add_argument("--link", default=None, help="stable port path to create (symlink to the pty)")
    ap.add_argument("--scenario", default=None, help="hidden-effects scenario file for the plant")
    ap.add_argument("--params-file", default=None, help="MBW params file for the plant")
    ap.add_argument("--faults", default="", help="random faults per line, e.g. garbage=0.001,unplug=1e-5")
    ap.add_argument("--seed", type=int, default=0)
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
    build : callable
        ``build(profile, rate, scenario, params_file, seed) -> EmulatedDevice``; the console script
        (:func:`hyst_bringup.emulator.main`) passes one on the sim's plant.
    """
    if build is None:
        raise TypeError("main() needs build=: a factory of EmulatedDevice (see hyst_bringup.emulator)")
    args = _parse(argv)
    try:
        rates = FaultRates.parse(args.faults)
        dev = build(args.profile, args.rate, args.scenario, args.params_file, args.seed)
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
    emu = PtyEmulator(dev, args.link, rates, seed=args.seed)
    try:
        emu.start()
    except OSError as err:
        print(f"hyst_emulator: cannot create the port at {emu.link}: {err}", file=sys.stderr)
        return 2
    print(f"hyst_emulator: {args.profile} stage at {args.rate:g} Hz on {emu.link} (pty {emu.pty_name}); "
          f"protocols ascii (HDB/1) and gcs", flush=True)
    print(f"  hyst_driver_node --ros-args -p port:={emu.link} -p profile:={args.profile}", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        emu.stop()
        print(f"hyst_emulator: stopped; faults injected {emu.injected}", flush=True)
    return 0
