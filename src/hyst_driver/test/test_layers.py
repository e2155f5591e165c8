"""House rule 1: in hyst_driver only driver_node imports rclpy; protocols, safety, transport and emulator do not."""
import subprocess
import sys

CORE = ("hyst_driver", "hyst_driver.protocol_ascii", "hyst_driver.protocol_gcs", "hyst_driver.adapter",
        "hyst_driver.safety", "hyst_driver.transport", "hyst_driver.emulator", "hyst_driver.errors")


def _imports_rclpy(modules) -> str:
    code = "import sys\n" + "".join(f"import {m}\n" for m in modules) + "print('rclpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_core_modules_do_not_import_rclpy():
    assert _imports_rclpy(CORE) == "False"


def test_the_probe_sees_the_node_module_import_rclpy():
    assert _imports_rclpy(["hyst_driver.driver_node"]) == "True"
