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


def test_the_launch_file_starts_the_nodes_bringup_starts_with_the_same_files_and_remaps():
    """launch/launch_ros are not installable here: the launch file is checked by its source. It takes
    the node table (package, executable, parameter file) from arm_ros.processes, which `bringup` and
    NodeProcess use, and a camera preset's parameters and remaps from camera_presets, as bringup does;
    where launch can be imported, its description is generated too."""
    import ast
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[1] / "launch" / "arm_pipeline.launch.py"
    tree = ast.parse(path.read_text())
    imported = {(n.module, a.name) for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) for a in n.names}
    assert ("arm_ros.processes", "NODES") in imported
    assert {("arm_bringup.camera_presets", name) for name in ("node_parameters", "node_remappings")} <= imported
    assigned = {t.id for n in ast.walk(tree) if isinstance(n, ast.Assign) for t in n.targets if isinstance(t, ast.Name)}
    assert "NODES" not in assigned, "the launch file keeps no node table of its own"
    if importlib.util.find_spec("launch") is not None and importlib.util.find_spec("launch_ros") is not None:
        spec = importlib.util.spec_from_file_location("arm_pipeline_launch", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        assert module.generate_launch_description().entities
