"""The emulated amplifier + sensor behind :class:`hyst_driver.emulator.PtyEmulator`: :class:`EmulatedDevice`
answers both protocols' frames (HDB/1 lines start with ``$``, anything else is GCS-like) and steps the injected
plant once per sample; :class:`FaultRates` are the random faults the pty side injects. Re-exported by
:mod:`.emulator`.
"""
from __future__ import annotations

from array import array
from dataclasses import dataclass

from . import protocol_ascii as hdb
from . import protocol_gcs as gcs
from .errors import ProtocolError

__all__ = ["EmulatedDevice", "FaultRates", "FAULTS"]

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
