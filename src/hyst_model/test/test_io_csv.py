"""CSV IO: SI native format, column/unit options, and clear errors."""
import re
from pathlib import Path
import numpy as np
import pytest

from hyst_model.errors import DataError
from hyst_model.io import read_csv, write_csv
from hyst_model.io.csvio import read_input_csv


def test_native_round_trip(tmp_path):
    t = np.arange(100) * 2e-4
    u = np.sin(t) * 150
    y = 1e-7 * u - 1.6e-6
    write_csv(tmp_path / "d.csv", {"t": t, "u": u, "y": y})
    rec = read_csv(tmp_path / "d.csv")
    np.testing.assert_allclose(rec.y, y, rtol=1e-9)
    np.testing.assert_allclose(rec.t, t, rtol=1e-9)


def test_columns_and_units_convert_to_si(tmp_path):
    p = tmp_path / "x.csv"
    p.write_text("time_ms,voltage_V,displacement_um,other\n0,0,-1.6,9\n0.2,1.5,-1.5,9\n0.4,3,-1.4,9\n")
    rec = read_csv(p, columns="time_ms,voltage_V,displacement_um", units="ms,V,um")
    np.testing.assert_allclose(rec.t, [0, 2e-4, 4e-4])
    np.testing.assert_allclose(rec.y, [-1.6e-6, -1.5e-6, -1.4e-6])
    # units inferred from the name suffix when --units is omitted
    np.testing.assert_allclose(read_csv(p, columns="time_ms,voltage_V,displacement_um").y, rec.y)


#: The public piezo record lives beside the checkout (../shared/data, see README "Data"); a user's clone may not
#: have it.
PIEZO = Path(__file__).resolve().parents[4] / "shared" / "data" / "piezo_150V_1Hz" / "piezo_150V_1Hz.csv"


@pytest.mark.skipif(not PIEZO.exists(), reason=f"shared data not present ({PIEZO})")
def test_real_piezo_header_reads_in_si():
    rec = read_csv(PIEZO, columns="t_s,voltage_V,displacement_um", units="s,V,um")
    assert len(rec) == 50001 and abs(rec.y[0] + 1.617e-6) < 1e-9 and rec.u.max() == 150.0


@pytest.mark.parametrize("columns,units,match", [
    (None, None, r"column\(s\) t, u, y not in the header.*--columns"),
    ("t_s,volts,displacement_um", None, r"column\(s\) volts not in the header"),
    ("t_s,voltage_V,displacement_um", "s,V,furlong", r"unknown unit 'furlong' for y"),
    ("t_s,voltage_V,displacement_um", "s,um,um", r"unknown unit 'um' for u"),
    ("t_s,voltage_V,displacement_um", "s,V", r"--units needs 3"),
])
def test_bad_options_give_one_clear_error(tmp_path, columns, units, match):
    p = tmp_path / "x.csv"
    p.write_text("t_s,voltage_V,displacement_um\n0,0,1\n1,1,2\n")
    with pytest.raises(DataError, match=match):
        read_csv(p, columns, units)


def test_nan_rows_reported(tmp_path):
    p = tmp_path / "n.csv"
    rows = "\n".join(f"{k * 1e-3},{k},{k * 1e-7}" for k in range(40))
    p.write_text("t,u,y\n" + rows.replace("0.005,5,5e-07", "0.005,,5e-07") + "\n")
    with pytest.raises(DataError, match=r"1 row\(s\) with NaN.*row 5, t = 0.005 s\)"):
        read_csv(p).check()


@pytest.mark.parametrize("row,why", [("0.001,1", "line 3 has 2 fields, the header 3"),
                                     ("0.001,1,2,3", "line 3 has 4 fields, the header 3")])
def test_a_row_with_a_field_too_few_or_too_many_is_one_line(tmp_path, row, why):
    """One too few came as numpy's two-line 'Some errors were detected !'; one too many was cut silently."""
    p = tmp_path / "r.csv"
    p.write_text(f"t,u,y\n0,1,2\n{row}\n0.002,1,2\n")
    with pytest.raises(DataError) as err:
        read_csv(p)
    assert why in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("sep", [";", "\t"])
def test_another_separator_is_named_not_sent_to_columns(tmp_path, sep):
    p = tmp_path / "s.csv"
    p.write_text(sep.join("tuy") + "\n" + sep.join(["0", "1", "2"]) + "\n")
    with pytest.raises(DataError, match=re.escape(f"separated by {sep!r}; hyst reads comma-separated CSV")):
        read_csv(p)


def test_empty_and_header_only(tmp_path):
    (tmp_path / "e.csv").write_text("")
    with pytest.raises(DataError, match="empty"):
        read_csv(tmp_path / "e.csv")
    (tmp_path / "h.csv").write_text("t,u,y\n")
    with pytest.raises(DataError, match="no data rows"):
        read_csv(tmp_path / "h.csv")


def test_write_refuses_overwrite_and_is_atomic(tmp_path):
    p = tmp_path / "o.csv"
    p.write_text("keep\n")
    with pytest.raises(DataError, match="exists"):
        write_csv(p, {"t": [0.0]})
    assert p.read_text() == "keep\n"
    write_csv(p, {"t": [0.0], "y": [1.0]}, force=True)
    assert p.read_text().splitlines()[0] == "t,y"
    assert [f.name for f in tmp_path.iterdir()] == ["o.csv"]  # no temporary left behind


def test_input_csv(tmp_path):
    p = tmp_path / "u.csv"
    p.write_text("t,u\n0,0\n0.001,1\n0.002,2\n")
    t, u = read_input_csv(p)
    np.testing.assert_allclose(u, [0, 1, 2])
    p.write_text("t,u\n0,0\n0.001,1\n0.001,2\n")
    with pytest.raises(DataError, match="not strictly increasing"):
        read_input_csv(p)
