"""The ``hyst_emulator`` command: the driver's emulator on the sim's plant, put together here."""
import subprocess
import sys

from hyst_bringup.emulator import build_device
from hyst_common.profiles import GMA


def test_build_device_drives_the_sim_plant_within_the_profile():
    dev = build_device("gma", 1000.0)
    assert dev.v_range == (GMA.v_min, GMA.v_max)
    assert type(dev.plant).__module__ == "hyst_sim.plant"


def test_help_and_bad_profile():
    run = [sys.executable, "-c", "import sys; from hyst_bringup.emulator import main; sys.exit(main())"]
    out = subprocess.run(run + ["--help"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "--profile" in out.stdout
    bad = subprocess.run(run + ["--faults", "nonsense=1"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and bad.stderr.startswith("hyst_emulator:")


def test_a_custom_stage_needs_its_model_and_range_on_the_command_line(tmp_path):
    run = [sys.executable, "-c", "import sys; from hyst_bringup.emulator import main; sys.exit(main())"]
    for args, why in ((["--profile", "custom", "--v-min", "-10", "--v-max", "10"], "needs --params-file"),
                      (["--profile", "custom", "--params-file", str(tmp_path / "p.yaml")], "needs --v-min"),
                      (["--v-min", "0", "--v-max", "100"], "custom stage")):
        r = subprocess.run(run + args, capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and why in r.stderr and "Traceback" not in r.stderr, (args, r.stderr)
