#!/usr/bin/env bash
# Idempotent set-up from nothing: Debian packages for headless EGL rendering, the project venv with
# pinned dependencies, the CMake path fix-up for the ROS 2 wheels, and `colcon build`.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD

need_apt=()
for pkg in libegl1 libegl-mesa0 libgl1-mesa-dri cmake g++; do
  dpkg -s "$pkg" >/dev/null 2>&1 || need_apt+=("$pkg")
done
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "[bootstrap] apt-get install ${need_apt[*]}"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need_apt[@]}"
fi

if [ ! -x .venv/bin/python ]; then
  echo "[bootstrap] creating .venv"
  python3 -m venv .venv
fi
req_hash=$(cat requirements.txt requirements-dev.txt | sha256sum | cut -d' ' -f1)
if [ "$(cat .venv/.requirements.sha 2>/dev/null)" != "$req_hash" ]; then
  echo "[bootstrap] pip install -r requirements.txt -r requirements-dev.txt"
  .venv/bin/python -m pip install -q --disable-pip-version-check "pip<25" "setuptools==79.0.1"
  .venv/bin/python -m pip install -q --disable-pip-version-check -r requirements.txt -r requirements-dev.txt
  .venv/bin/python scripts/fix_cmake_paths.py .venv
  echo "$req_hash" > .venv/.requirements.sha
fi

export AMENT_PREFIX_PATH="$ROOT/.venv" CMAKE_PREFIX_PATH="$ROOT/.venv"
export PATH="$ROOT/.venv/bin:$PATH"
# Interface packages missing from the ROS 2 wheels (tf2_msgs, control_msgs) are built from compat/
# with the same names and fields; each one the venv holds is left out. src/ is the product, lab/ the
# benchmarks and training. A robot's workspace on a full ROS 2 install builds src/ alone and uses the
# real interface packages.
base_paths=(src lab)
for interfaces in tf2_msgs control_msgs; do
  env -u PYTHONPATH .venv/bin/python -c "import $interfaces" 2>/dev/null || base_paths+=("compat/$interfaces")
done
src_hash=$( (echo "${base_paths[*]}"; find "${base_paths[@]}" colcon.meta -type f \( -name '*.msg' -o -name '*.action' -o -name '*.txt' -o -name '*.xml' -o -name 'setup.py' -o -name 'setup.cfg' -o -name 'colcon.meta' -o -name '*.yaml' -o -name '*.launch.py' \) -print0 | sort -z | xargs -0 sha256sum) | sha256sum | cut -d' ' -f1)
if [ "$(cat install/.src.sha 2>/dev/null)" != "$src_hash" ] || [ ! -f install/setup.bash ]; then
  echo "[bootstrap] colcon build"
  colcon --log-base log build --base-paths "${base_paths[@]}" --symlink-install --metas colcon.meta \
    --event-handlers console_cohesion- status- summary+ >/dev/null
  echo "$src_hash" > install/.src.sha
fi
echo "[bootstrap] ready"
