"""Driver benchmarks: protocol encode/decode cost, limiter cost, and request/reply round trip over a pty.

``python bench/bench_driver.py`` or ``make bench``; ``main()`` returns a markdown table.
The round trip is host → pty → emulator thread (same process, so it includes GIL hand-offs) → pty → host;
a separate emulator process or a real USB-CDC device is typically faster per hop but adds the USB frame time.
"""
from __future__ import annotations

import select
import statistics
import time
import timeit

from hyst_bringup.emulator import build_device
from hyst_driver import protocol_ascii as hdb
from hyst_driver import protocol_gcs as gcs
from hyst_driver.adapter import AsciiAdapter, GcsAdapter
from hyst_driver.emulator import PtyEmulator
from hyst_driver.safety import Limits, VoltageLimiter
from hyst_driver.transport import SerialTransport


def _per_call_us(stmt, number: int = 20000) -> float:
    best = min(timeit.repeat(stmt, number=number, repeat=3))
    return best / number * 1e6


def _codec_rows() -> list[tuple[str, str]]:
    frame = hdb.encode_sample(hdb.Sample(17, 1017000, 7500, 75_000_000))
    stream = frame * 1000
    ad, gad = AsciiAdapter(), GcsAdapter()
    lim = VoltageLimiter(Limits(0.0, 150.0, 1e5, 0.0))
    vals = iter(range(10**9))

    def feed_gcs() -> None:
        gad.poll()
        gad.feed(b"1=15.0020\n1=75.000000\n")

    rows = [
        ("HDB/1 encode `SV` (volts → frame)", f"{_per_call_us(lambda: ad.set_voltage(75.123456)):.2f} µs"),
        ("HDB/1 decode `P` frame (CRC + parse)", f"{_per_call_us(lambda: hdb.decode_reply(frame)):.2f} µs"),
        ("HDB/1 adapter feed, per frame (1000 frames/chunk)",
         f"{_per_call_us(lambda: ad.feed(stream), number=20) / 1000:.2f} µs"),
        ("GCS encode `SVA`", f"{_per_call_us(lambda: gcs.encode_sva(75.123456)):.2f} µs"),
        ("GCS adapter poll + feed (`POS?`/`VOL?` pair)", f"{_per_call_us(feed_gcs):.2f} µs"),
        ("limiter update (request + slew step)", f"{_per_call_us(lambda: lim.update(next(vals) % 150, 1e-3)):.2f} µs"),
    ]
    return rows


def _round_trip(protocol: str, n: int = 400) -> tuple[float, float, float]:
    """Median, p99 and max (ms) of request → complete reply over a pty to the emulator thread."""
    with PtyEmulator(build_device("pea", 1000.0)) as emu:
        t = SerialTransport(emu.link)
        assert t.try_open(0.0)
        fd = t.fileno()
        req = hdb.encode_read_position() if protocol == "ascii" else gcs.encode_pos_query() + gcs.encode_vol_query()
        want = 1 if protocol == "ascii" else 2
        out = []
        for _ in range(n + 20):
            t.read()
            t0 = time.perf_counter()
            t.write(req)
            buf = b""
            while buf.count(b"\n") < want and time.perf_counter() - t0 < 0.5:
                select.select([fd], [], [], 0.05)
                buf += t.read()
            out.append(time.perf_counter() - t0)
        t.close()
    out = sorted(out[20:])
    return statistics.median(out) * 1e3, out[int(0.99 * (len(out) - 1))] * 1e3, out[-1] * 1e3


def main() -> str:
    rows = _codec_rows()
    for proto, what in (("ascii", "`$RP` → `$P` sample"), ("gcs", "`POS?`+`VOL?` → 2 replies")):
        p50, p99, mx = _round_trip(proto)
        rows.append((f"pty round trip {proto}: {what}", f"p50 {p50:.3f} ms, p99 {p99:.3f} ms, max {mx:.2f} ms"))
    lines = ["| operation | cost |", "|---|---|"] + [f"| {a} | {b} |" for a, b in rows]
    return "\n".join(lines)


if __name__ == "__main__":
    print(main())
