"""House rule 1: rclpy is imported only by the *_node.py modules and composed.py."""
import subprocess
import sys

CORE = ("hyst_control", "hyst_control.base", "hyst_control.dppc", "hyst_control.dmrac", "hyst_control.pid",
        "hyst_control.reference", "hyst_control.controllers", "hyst_bringup.loop", "hyst_bringup.cli_track",
        "hyst_bringup.demo", "hyst_control.stability", "hyst_control.compensation", "hyst_control.controller_settings")


def test_core_and_cli_modules_do_not_import_rclpy():
    code = "import sys\n" + "".join(f"import {m}\n" for m in CORE) + "print('rclpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_node_modules_do_import_rclpy():  # the check above can fail: the same probe sees a node module's rclpy
    code = "import sys\nimport hyst_control.reference_node\nprint('rclpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "True"
