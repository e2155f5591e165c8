"""HDB/1 ASCII protocol: byte-for-byte vectors, CRC known answer, round trips and every rejection path."""
from __future__ import annotations

import pytest

from hyst_driver import protocol_ascii as p
from hyst_driver import protocol_ascii as hdb
from hyst_driver.errors import ChecksumError, EncodeError, ProtocolError


def test_crc8_known_answer():
    # CRC-8/SMBUS catalogue check value (reveng): poly 0x07, init 0, "123456789" -> 0xF4.
    assert p.crc8(b"123456789") == 0xF4
    assert p.crc8(b"") == 0x00


def _crc_bitwise(data: bytes) -> int:
    c = 0
    for b in data:
        c ^= b
        for _ in range(8):
            c = ((c << 1) ^ 0x07) & 0xFF if c & 0x80 else (c << 1) & 0xFF
    return c


@pytest.mark.parametrize("body", [b"ID", b"SV,75000000", b"P,65535,4294967295,-2147483647,-999999999"])
def test_table_crc_equals_bitwise_crc(body):
    assert p.crc8(body) == _crc_bitwise(body)


@pytest.mark.parametrize("frame_bytes, fn", [
    (b"$ID*3D\r\n", p.encode_identify),
    (b"$RP*91\r\n", p.encode_read_position),
    (b"$SP*84\r\n", p.encode_stop_stream),
    (b"$ST,1000*79\r\n", lambda: p.encode_start_stream(1000)),
    (b"$SV,75000000*A5\r\n", lambda: p.encode_set_voltage(75_000_000)),
    (b"$SV,-2500000*B2\r\n", lambda: p.encode_set_voltage(-2_500_000)),
    (b"$SV,0*5D\r\n", lambda: p.encode_set_voltage(0)),
])
def test_host_frames_byte_for_byte(frame_bytes, fn):
    assert fn() == frame_bytes


@pytest.mark.parametrize("frame_bytes, msg", [
    (b"$P,17,1017000,7500,75000000*07\r\n", p.Sample(17, 1017000, 7500, 75_000_000)),
    (b"$OK,ST,1000*83\r\n", p.Ack("ST", ("1000",))),
    (b"$OK,SP*D4\r\n", p.Ack("SP")),
    (b"$ER,1,checksum error in received frame*64\r\n", p.ErrorReply(1, "checksum error in received frame")),
    (b"$ID,hyst,HDB-EMU,0001,1.0*10\r\n", p.Identity("hyst", "HDB-EMU", "0001", "1.0")),
])
def test_device_frames_byte_for_byte_both_ways(frame_bytes, msg):
    encoders = {p.Sample: p.encode_sample, p.Identity: p.encode_identity,
                p.ErrorReply: lambda m: p.encode_error(m.code, m.text),
                p.Ack: lambda m: p.encode_ack(m.command, *m.args)}
    assert encoders[type(msg)](msg) == frame_bytes
    assert p.decode_reply(frame_bytes) == msg


@pytest.mark.parametrize("frame_bytes, cmd", [
    (b"$ID*3D\r\n", p.Identify()), (b"$RP*91\r\n", p.ReadPosition()), (b"$SP*84\r\n", p.StopStream()),
    (b"$ST,1000*79\r\n", p.StartStream(1000)), (b"$SV,-2500000*B2\r\n", p.SetVoltage(-2_500_000)),
])
def test_decode_command(frame_bytes, cmd):
    assert p.decode_command(frame_bytes) == cmd


def test_volts_to_uv_rounds_and_rejects():
    assert p.volts_to_uv(75.0) == 75_000_000
    assert p.volts_to_uv(1.0000004) == 1_000_000
    assert p.volts_to_uv(-4.9999996) == -5_000_000
    for bad in (float("nan"), float("inf"), -float("inf"), 1000.0, -1e300, "5"):
        with pytest.raises(EncodeError):
            p.volts_to_uv(bad)
    with pytest.raises(EncodeError):
        p.encode_set_voltage(1.5)  # must be integer microvolts
    with pytest.raises(EncodeError):
        p.encode_set_voltage(10**9)
    with pytest.raises(EncodeError):
        p.encode_start_stream(0)


def test_every_single_bit_flip_is_detected():
    good = p.encode_sample(p.Sample(17, 1017000, 7500, 75_000_000))
    assert p.decode_reply(good) == p.Sample(17, 1017000, 7500, 75_000_000)  # the unflipped frame decodes
    for i in range(1, len(good) - 2):  # flip every bit between '$' and "\r\n"
        for bit in range(8):
            bad = bytearray(good)
            bad[i] ^= 1 << bit
            with pytest.raises(ProtocolError):
                p.decode_reply(bytes(bad))


def test_checksum_error_is_distinguished():
    with pytest.raises(ChecksumError):
        p.decode_reply(b"$P,17,1017000,7500,75000001*07\r\n")
    with pytest.raises(ChecksumError):
        p.decode_reply(b"$P,17,1017000,7500,75000000*07".replace(b"*07", b"*08"))


@pytest.mark.parametrize("line", [
    b"", b"garbage", b"P,17,1,2,3*00", b"$P,17,1017000,7500*XX", b"$P,17,1017000,7500",
    b"$" + b"A" * 120 + b"*00", b"$*00", b"$p,1*%02X" % p.crc8(b"p,1"),
    b"$P,1,2,3*%02X" % p.crc8(b"P,1,2,3"),                       # wrong field count
    b"$P,01,2,3,4*%02X" % p.crc8(b"P,01,2,3,4"),                 # leading zero
    b"$P,+1,2,3,4*%02X" % p.crc8(b"P,+1,2,3,4"),                 # plus sign
    b"$P,65536,2,3,4*%02X" % p.crc8(b"P,65536,2,3,4"),           # seq out of range
    b"$P,1,2,3,1000000000*%02X" % p.crc8(b"P,1,2,3,1000000000"),  # uV out of range
    b"$P,17,1017000,7500,75000000*07".lower(),                    # lower-case hex is not the format
    b"$XX*%02X" % p.crc8(b"XX"),
])
def test_malformed_replies_raise_protocol_error(line):
    with pytest.raises(ProtocolError):
        p.decode_reply(line)


def test_resync_on_last_dollar_recovers_spliced_frame():
    good = p.encode_sample(p.Sample(3, 3000, -12, 1_500_000))
    spliced = good[:11] + good  # a truncated frame without its line end, then a complete one
    assert p.decode_reply(spliced) == p.Sample(3, 3000, -12, 1_500_000)


def test_frame_refuses_unframable_bodies():
    for body in ("", "A$B", "A*B", "é", "x" * 100):
        with pytest.raises(EncodeError):
            p.frame(body)
    with pytest.raises(EncodeError):
        p.encode_identity(p.Identity("a,b", "m", "s", "f"))


def test_line_framer_splits_buffers_and_drops_overlong():
    f = p.LineFramer(max_line=20)
    assert f.feed(b"$ab") == []
    assert f.feed(b"c\r\n$de") == [b"$abc"]
    assert f.feed(b"f\n") == [b"$def"]
    assert f.feed(b"x" * 50) == []           # overlong, still unterminated
    assert f.feed(b"yyy\n$ok\n") == [b"$ok"]  # the rest of the overlong line is skipped
    assert f.overlong == 1
    assert f.feed(b"z" * 25 + b"\n") == [] and f.overlong == 2
    f.feed(b"$partial")
    f.reset()
    assert f.feed(b"\n$x\n") == [b"", b"$x"]


def test_noise_without_a_newline_before_a_frame_costs_only_the_noise():
    """72+ bytes of noise then a good frame: the frame was dropped with the noise (69 bytes: kept)."""
    from hyst_driver.adapter import AsciiAdapter, BadFrame, Reading

    good = hdb.encode_sample(hdb.Sample(1, 1000, 5000, 75_000_000))
    for n in (72, 100, 300):
        for chunks in ([b"\x01" * n + good], [b"\x01" * n, good], [b"\x01" * n + good[:5], good[5:]]):
            a = AsciiAdapter()
            ev = [e for c in chunks for e in a.feed(c)]
            assert [type(e) for e in ev] == [BadFrame, Reading] and ev[0].kind == "overlong", (n, chunks, ev)


def test_encoders_refuse_what_the_decoders_refuse_and_a_newline_is_no_field():
    with pytest.raises(EncodeError):
        hdb.volts_to_uv(1e303)   # OverflowError before
    with pytest.raises(EncodeError):
        hdb.volts_to_uv(True)    # 1 000 000 µV before
    for code in (1000, -1):
        with pytest.raises(EncodeError):
            hdb.encode_error(code)
    with pytest.raises((EncodeError, ProtocolError)):
        hdb.frame("ID\n")        # b'$ID\n*85\r\n' before: one frame the receiver splits in two
    with pytest.raises(ProtocolError):
        hdb.decode_reply(b"$P,1,2,3,4\n*3B")


def test_a_sample_behind_the_last_is_reported_not_counted_as_65534_lost():
    from hyst_driver.adapter import AsciiAdapter, BadFrame, Reading

    a = AsciiAdapter()
    frames = [hdb.encode_sample(hdb.Sample(s, 1000 * s, 5000, 75_000_000)) for s in (10, 11, 10, 12, 14)]
    ev = [e for f in frames for e in a.feed(f)]
    assert [type(e) for e in ev] == [Reading, Reading, BadFrame, Reading, Reading] and ev[2].kind == "unexpected"
    assert a.lost_samples == 1  # 13 only
