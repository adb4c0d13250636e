"""bringup's Graph with real node processes: with the sim running, every other node runs on its clock."""

import time

from arm_bringup.bringup import Graph
from arm_bringup.demo import first_silent_stage
from arm_ros.common import use_private_domain
from arm_ros.processes import node_built

SMALL_SIM = ("-p", "n_objects:=1", "-p", "width:=64", "-p", "height:=48")


def test_graph_runs_the_nodes_on_sim_time_and_stops_them_with_exit_code_0(tmp_path):
    use_private_domain()
    assert node_built("sim") and node_built("segmentation"), "make setup builds the nodes"
    with Graph(tmp_path, use_sim_time=True) as graph:
        sim = graph.start("sim", *SMALL_SIM)
        segmentation = graph.start("segmentation")
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and "sim ready" not in sim.log():
            time.sleep(0.2)
        alive = graph.alive()
    codes = {key: process.process.returncode for key, process in graph.processes.items()}
    assert "use_sim_time:=true" in segmentation.cmd and "use_sim_time:=true" not in sim.cmd
    assert alive == {"sim": True, "segmentation": True}, (sim.log(), segmentation.log())
    assert codes == {"sim": 0, "segmentation": 0}, (sim.log(), segmentation.log())


def test_first_silent_stage_names_the_first_stage_without_output():
    stages = ["segmentation", "reconstruction", "planner"]
    assert first_silent_stage(stages, "labels", None, None) == "reconstruction"
    assert first_silent_stage(stages, "labels", "meshes", {"task": "grasp"}) is None
    assert first_silent_stage(["segmentation"], None, None, None) == "segmentation"
