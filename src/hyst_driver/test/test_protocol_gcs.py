"""GCS-like protocol: byte-for-byte vectors and rejection paths."""
from __future__ import annotations

import pytest

from hyst_driver import protocol_gcs as g
from hyst_driver.errors import EncodeError, ProtocolError


def test_host_commands_byte_for_byte():
    assert g.encode_idn() == b"*IDN?\n"
    assert g.encode_servo_off() == b"SVO 1 0\n"
    assert g.encode_sva(75.0) == b"SVA 1 75.000000\n"
    assert g.encode_sva(-4.9999996) == b"SVA 1 -5.000000\n"
    assert g.encode_sva(-1e-9) == b"SVA 1 0.000000\n"  # never "-0.000000"
    assert g.encode_pos_query() == b"POS? 1\n"
    assert g.encode_vol_query() == b"VOL? 1\n"
    assert g.encode_err_query() == b"ERR?\n"


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf"), 1000.0, -1e300, True, "1"])
def test_sva_refuses_unencodable(bad):
    with pytest.raises(EncodeError):
        g.encode_sva(bad)


def test_replies_decode():
    assert g.decode_reply(b"1=15.002000\n", "POS?") == g.AxisValue("1", 15.002)
    assert g.decode_reply(b"1=-0.5\r\n", "VOL?") == g.AxisValue("1", -0.5)
    assert g.decode_reply(b"17\n", "ERR?") == g.ErrorCode(17)
    assert g.decode_reply(b"hyst,GCS-EMU,0001,1.0\n", "*IDN?") == g.IdnReply("hyst,GCS-EMU,0001,1.0")
    assert g.encode_axis_value(15.002) == b"1=15.002000\n"
    assert g.encode_error_code(0) == b"0\n"


@pytest.mark.parametrize("line, expect", [
    (b"2=1.0\n", "POS?"), (b"1=\n", "POS?"), (b"1=nan\n", "VOL?"), (b"1=inf\n", "VOL?"), (b"1=1e999\n", "VOL?"),
    (b"1=12.31=75.0\n", "POS?"), (b"1=1.0\x00\n", "POS?"), (b"\xff\xfe\n", "POS?"), (b"x\n", "ERR?"),
    (b"1=5\n", "*IDN?"), (b"", "*IDN?"), (b"1=" + b"9" * 200 + b"\n", "POS?"),
])
def test_bad_replies_raise(line, expect):
    with pytest.raises(ProtocolError):
        g.decode_reply(line, expect)


def test_commands_decode_with_gcs_error_codes():
    assert g.decode_command(b"SVA 1 75.000000\n") == g.SetOpenLoop(75.0)
    assert g.decode_command(b"POS? 1\n") == g.PosQuery()
    assert g.decode_command(b"VOL? 1\n") == g.VolQuery()
    assert g.decode_command(b"SVO 1 0\n") == g.ServoOff()
    assert g.decode_command(b"*IDN?\n") == g.Idn()
    assert g.decode_command(b"ERR?\n") == g.ErrQuery()
    for line, code in [(b"FOO 1\n", 2), (b"SVA 2 1.0\n", 15), (b"SVA 1 x\n", None), (b"SVO 1 1\n", 17),
                       (b"SVA 1\n", 1), (b"\n", 1)]:
        with pytest.raises(ProtocolError) as info:
            g.decode_command(line)
        if code is not None:
            assert info.value.args[1] == code
