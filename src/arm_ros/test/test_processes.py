"""arm_ros.processes against the installed workspace: a real node executable (sim_node) started,
stopped with SIGINT, and the parameter files arm_bringup installs. The node packages are downstream
of arm_ros, so they are found through the ament index at run time (no test_depend: it would make a
cycle), and `make test` builds them all first."""

import signal
import time

import pytest
import yaml

from arm_ros.common import use_private_domain
from arm_ros.processes import NODES, NodeProcess, config_file, executable, node_built

SMALL_SIM = {"n_objects": 1, "width": 64, "height": 48, "camera_rate_hz": 1.0}


@pytest.fixture(scope="module", autouse=True)
def private_domain():
    use_private_domain()


def wait_for_text(process: NodeProcess, text: str, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and process.alive():
        if text in process.log():
            return True
        time.sleep(0.1)
    return text in process.log()


def test_every_node_executable_is_installed():
    missing = [f"{key}: {executable(key)}" for key in NODES if not node_built(key)]
    assert not missing, f"not built (make setup): {missing}"


def test_config_file_finds_the_installed_yaml_of_every_node():
    for key, (_, node_name, file_name) in NODES.items():
        if file_name is None:
            continue
        path = config_file(file_name)
        assert path is not None and path.parent.name == "config" and path.parent.parent.name == "arm_bringup", key
        assert "ros__parameters" in yaml.safe_load(path.read_text())[node_name], path
    assert config_file("no_such_node.yaml") is None


def test_sim_node_starts_with_its_parameter_file_and_exits_0_on_sigint(tmp_path):
    process = NodeProcess("sim", tmp_path / "sim.log", params=SMALL_SIM, remaps={"clock": "sim_clock"})
    try:
        assert process.cmd[0] == str(executable("sim"))
        assert process.cmd[process.cmd.index("--params-file") + 1] == str(config_file("sim_node.yaml"))
        assert "n_objects:=1" in process.cmd and "clock:=sim_clock" in process.cmd
        assert wait_for_text(process, "sim ready: 1 objects", 60.0), process.log()
        assert process.rss_mb() > 10.0 and process.cpu_s() > 0.1  # loading MuJoCo and rclpy took CPU
    finally:
        code = process.stop(signal.SIGINT, timeout_s=15.0)
    assert code == 0, process.log()
    assert not process.alive() and process.rss_mb() != process.rss_mb()  # nan once it is gone
    assert process.cpu_s() != process.cpu_s()


def test_an_invalid_parameter_ends_the_node_with_exit_code_2(tmp_path):
    process = NodeProcess("sim", tmp_path / "sim.log", params={**SMALL_SIM, "n_objects": 1000})
    code = process.wait(60.0)
    if code is None:
        process.stop()
    assert code == 2 and "n_objects" in process.log(), process.log()
