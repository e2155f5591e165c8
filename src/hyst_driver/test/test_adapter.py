"""Adapters: SI scaling, event classification, GCS reply pairing and desynchronisation recovery."""
from __future__ import annotations

import pytest

from hyst_driver import protocol_ascii as hdb
from hyst_driver.adapter import (AsciiAdapter, BadFrame, DeviceFault, GcsAdapter, Identified, Reading,
                                 make_adapter)
from hyst_driver.errors import ConfigError


def test_ascii_scales_counts_and_microvolts_to_si():
    ad = AsciiAdapter(counts_to_m=2e-9)
    ev = ad.feed(hdb.encode_sample(hdb.Sample(1, 1000, 7500, 75_000_000)))
    assert ev == [Reading(7500 * 2e-9, 75.0, 1, 1e-3)]
    assert ad.set_voltage(75.0) == b"$SV,75000000*A5\r\n"
    assert ad.poll() == b"" and ad.streaming


def test_ascii_events_split_across_reads_and_bad_frames_counted():
    ad = AsciiAdapter(2e-9, v_plausible=(-15.0, 165.0))
    stream = (hdb.encode_identity(hdb.Identity("a", "b", "c", "d")) + b"\x00\xffjunk\n"
              + hdb.encode_sample(hdb.Sample(5, 0, 1, 1_000_000)).replace(b"*", b"*0")     # syntax
              + b"$P,6,0,1,1000000*00\r\n"                                              # checksum
              + hdb.encode_sample(hdb.Sample(9, 0, -3, 170_000_000))                    # implausible
              + hdb.encode_error(5) + hdb.encode_error(3)
              + hdb.encode_sample(hdb.Sample(7, 0, 2, 2_000_000))
              + hdb.encode_sample(hdb.Sample(10, 0, 2, 2_000_000)))
    events = []
    for i in range(0, len(stream), 7):  # arbitrary chunking must not matter
        events += ad.feed(stream[i:i + 7])
    kinds = [e.kind if isinstance(e, BadFrame) else type(e).__name__ for e in events]
    assert kinds == ["Identified", "garbage", "syntax", "syntax", "checksum", "implausible", "DeviceFault",
                     "DeviceFault", "Reading", "Reading"]
    assert events[6] == DeviceFault(5, hdb.ERROR_CODES[5], severe=True) and not events[7].severe
    assert ad.lost_samples == 2  # 7 -> 10
    spliced = hdb.encode_sample(hdb.Sample(11, 0, 5, 0))[:9] + hdb.encode_sample(hdb.Sample(12, 0, 6, 0))
    assert [type(e).__name__ for e in ad.feed(spliced)] == ["BadFrame", "Reading"]
    ad.reset()
    assert ad.feed(hdb.encode_sample(hdb.Sample(100, 0, 0, 0)))[0].seq == 100 and ad.lost_samples == 3


def test_gcs_pairs_replies_in_query_order():
    ad = GcsAdapter(v_plausible=(-15.0, 165.0))
    assert ad.identify() == b"*IDN?\n"
    assert ad.read_once() == b"POS? 1\nVOL? 1\n"
    ev = ad.feed(b"hyst,GCS-EMU,1,1\n1=15.0020\n1=75.000000\n")
    assert ev == [Identified("hyst,GCS-EMU,1,1"), Reading(pytest.approx(15.002e-6), 75.0, None)]
    assert not ad.busy
    ad.poll()
    assert ad.error_query() == b"ERR?\n"
    ev = ad.feed(b"1=1.0\n1=2.0\n1000\n")
    assert isinstance(ev[0], Reading)
    assert ev[1] == DeviceFault(1000, "amplifier fault (overload or over-temperature)", True)


def _synced_gcs() -> GcsAdapter:
    ad = GcsAdapter(v_plausible=(-15.0, 165.0))
    assert ad.identify() == b"*IDN?\n"
    assert ad.feed(b"hyst,GCS-EMU,1,1\n") == [Identified("hyst,GCS-EMU,1,1")] and ad.synchronised
    return ad


def _kinds(events) -> list[str]:
    return [e.kind if isinstance(e, BadFrame) else type(e).__name__ for e in events]


def test_gcs_bad_line_resynchronises_instead_of_mispairing():
    ad = _synced_gcs()
    assert ad.poll() == b"POS? 1\nVOL? 1\n"
    ev = ad.feed(b"1=12.31=75.0\n1=75.0\n")  # spliced partial POS? reply, then VOL? reply
    # desynchronised: not busy (the next poll goes at once, not after a sample timeout) and it carries a marker
    assert _kinds(ev) == ["syntax", "unexpected"] and not ad.synchronised and not ad.busy
    assert ad.poll() == b"*IDN?\nPOS? 1\nVOL? 1\n" and ad.busy
    # lines before the marker's reply are discarded, those after it paired
    ev = ad.feed(b"1=75.0\nhyst,GCS-EMU,1,1\n1=10.0\n1=500.0\n")
    assert _kinds(ev) == ["unexpected", "Identified", "implausible"] and ad.synchronised and not ad.busy
    ad.error_query()
    ad.poll()  # ERR? overtaken by a new exchange: its late answer is still reported, not dropped
    assert ad.feed(b"17\n1=1.0\n1=2.0\n") == [DeviceFault(17, "parameter out of range", False),
                                                Reading(pytest.approx(1e-6), 2.0, None)]


def test_gcs_late_reply_never_shifts_the_pairs():
    """The CI failure: a VOL? reply arriving after the next poll was taken for that poll's POS?, every later pair
    was shifted by one line, and the position (µm) read as the applied voltage (V) re-seeded the limiter."""
    ad = _synced_gcs()
    ad.poll()
    assert ad.feed(b"1=23.8440\n") == []  # POS? answered, VOL? late ...
    assert ad.busy
    assert ad.poll() == b"*IDN?\nPOS? 1\nVOL? 1\n"  # ... when the sample timeout polls again
    ev = ad.feed(b"1=119.218384\n")  # the late VOL? reply: discarded, not taken for the new POS?
    ev += ad.feed(b"hyst,GCS-EMU,1,1\n1=23.8440\n1=119.218384\n")
    for _ in range(2):
        assert not ad.busy and ad.poll() == b"POS? 1\nVOL? 1\n"
        ev += ad.feed(b"1=23.8440\n1=119.218384\n")
    assert _kinds(ev) == ["unexpected", "Identified", "Reading", "Reading", "Reading"]
    readings = [e for e in ev if isinstance(e, Reading)]
    assert len(readings) == 3 and all(r.applied_v == 119.218384 for r in readings)
    assert all(r.position_m == pytest.approx(23.844e-6) for r in readings)


def test_gcs_counts_pairs_across_markers_and_lost_marker_replies():
    ad = GcsAdapter()
    hs = ad.identify() + ad.read_once() + ad.read_once()  # the link's handshake: two read-backs after *IDN?
    assert hs == b"*IDN?\nPOS? 1\nVOL? 1\nPOS? 1\nVOL? 1\n"
    assert _kinds(ad.feed(b"1=9.0\n")) == ["unexpected"]  # from before the handshake: never paired
    assert _kinds(ad.feed(b"x,y\n1=1.0\n1=2.0\n1=3.0\n1=4.0\n")) == ["Identified", "Reading", "Reading"]
    assert ad.read_once() == b"POS? 1\nVOL? 1\n"  # synchronised: no marker
    ad.poll(), ad.poll()  # two resynchronising polls in flight; the first marker's reply is lost to garbage
    ev = ad.feed(b"1=5.0\n1=6.0\n\xff\xfe\n1=7.0\n1=8.0\nx,y\n1=9.0\n1=10.0\n")
    assert _kinds(ev)[-2:] == ["Identified", "Reading"] and ev[-1] == Reading(pytest.approx(9e-6), 10.0, None)
    assert not any(isinstance(e, Reading) for e in ev[:-2])
    assert _kinds(ad.feed(b"x,y\n")) == ["Identified"]  # the second marker's own reply
    assert _kinds(ad.feed(b"some,identity\n")) == ["unexpected"] and not ad.synchronised  # nobody asked


def test_make_adapter():
    assert make_adapter("gcs").name == "gcs" and make_adapter("ascii", 1e-9).counts_to_m == 1e-9
    with pytest.raises(ConfigError):
        make_adapter("scpi")
    with pytest.raises(ConfigError):
        AsciiAdapter(counts_to_m=0.0)


def test_reconnect_seed_ignores_samples_from_before_the_handshake():
    """A stream still running from the last connection: its samples were taken before the device read the
    handshake (and a setpoint still ahead of it in the FIFO); only read-backs after the identify reply seed."""
    from hyst_driver import protocol_ascii as hdb
    from hyst_driver.safety import Limits
    from hyst_driver.transport import DeviceLink

    class Port:
        url, last_error, is_open = "fake", "", True

        def __init__(self):
            self.rx, self.tx = b"", []

        def try_open(self, now):
            return True

        def read(self):
            data, self.rx = self.rx, b""
            return data

        def write(self, data):
            self.tx.append(data)

        def fileno(self):
            return None

        def close(self):
            pass

    port = Port()
    link = DeviceLink(port, make_adapter("ascii", 2e-9), Limits(0.0, 150.0, 2e4, 0.0, dt_max=1e-3), 1000)
    link.service(0.0)  # opens, sends the handshake
    uv = hdb.volts_to_uv
    port.rx = (hdb.encode_sample(hdb.Sample(1, 1000, 0, uv(50.0))) + hdb.encode_sample(hdb.Sample(2, 2000, 0, uv(50.0)))
               + hdb.encode_ack("SP") + hdb.encode_identity(hdb.Identity("a", "b", "c", "d")))
    link.service(0.001)
    assert link.health.state == "handshake"  # the stale 50 V pair seeds nothing
    port.rx = hdb.encode_sample(hdb.Sample(3, 3000, 0, uv(65.0))) + hdb.encode_sample(hdb.Sample(4, 4000, 0, uv(65.0)))
    link.service(0.002)  # the RP replies: the stale setpoint (65 V) has been applied
    assert link.health.state == "running" and link.limiter.confirmed == 65.0


def test_gcs_garbled_line_while_a_marker_is_out_does_not_wait_for_a_timeout():
    """A garbage burst's tail splices into the next line, often the marker's own reply: the adapter must not sit
    busy until the link's sample timeout (one timeout per burst, 90 per 100 bursts, before), but poll again at
    once with another marker; late value lines before a marker's reply do not end the wait."""
    ad = _synced_gcs()
    ad.poll()
    assert _kinds(ad.feed(b"\xca\xfe\n")) == ["syntax"] and not ad.busy
    assert ad.poll() == b"*IDN?\nPOS? 1\nVOL? 1\n" and ad.busy
    assert _kinds(ad.feed(b"1=20.65\n")) == ["unexpected"] and ad.busy  # a late line: still waiting
    assert _kinds(ad.feed(b"O\xf66-hyst,GCS-EMU,1,1\n")) == ["syntax"] and not ad.busy  # the reply, garbled
    assert ad.poll() == b"*IDN?\nPOS? 1\nVOL? 1\n"
    ev = ad.feed(b"1=1.0\n1=2.0\nhyst,GCS-EMU,1,1\n1=3.0\n1=4.0\n")
    assert _kinds(ev) == ["unexpected", "unexpected", "Identified", "Reading"] and ev[-1].applied_v == 4.0


@pytest.mark.parametrize("line", [b"--5\n", b"-\n", b"5-\n", b"-5-\n"])
def test_gcs_a_malformed_integer_line_is_a_bad_frame_not_an_exception(line):
    """'--5' passed lstrip('-').isdigit() into int(): a ValueError out of feed, which aborted the shutdown ramp."""
    ad = _synced_gcs()
    ev = ad.feed(line)
    assert all(isinstance(e, BadFrame) for e in ev) and ev
    assert [type(e) for e in ad.feed(b"-5\n")] == [DeviceFault]  # a real (negative) code still reads
