# Source me: the project venv, the colcon install space and headless rendering.
_arm_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
source "$_arm_root/.venv/bin/activate"
export AMENT_PREFIX_PATH="$_arm_root/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$_arm_root/.venv${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
source "$_arm_root/install/setup.bash"
export MUJOCO_GL="${MUJOCO_GL:-egl}"
export PYOPENGL_PLATFORM="${PYOPENGL_PLATFORM:-egl}"
export ARM_ROOT="$_arm_root"
unset _arm_root
# ros2cli is not installable here: put each package's executables (install/<pkg>/lib/<pkg>) on PATH,
# so `sim_node`, `bench_seg`, ... run as `ros2 run <pkg> <exe>` would on a full ROS 2 install.
for _arm_exe_dir in "$ARM_ROOT"/install/*/lib/*/; do
  case ":$PATH:" in *":${_arm_exe_dir%/}:"*) ;; *) PATH="${_arm_exe_dir%/}:$PATH" ;; esac
done
export PATH
unset _arm_exe_dir
