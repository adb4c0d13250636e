import pathlib
import time

import pytest

from arm_bringup.bringup import Graph
from arm_bringup.camera_presets import GRAPH_CAMERA_TOPICS, PresetError, load_preset, node_options
from arm_ros.common import use_private_domain
from arm_ros.processes import node_built
from arm_segmentation.segmentation_node import TOPICS

PRESETS = sorted((pathlib.Path(__file__).parents[1] / "config" / "cameras").glob("*.yaml"))
SEGMENTATION_CAMERA_TOPICS = {TOPICS[k][1] for k in ("rgb", "depth", "camera_info")}


def test_the_three_driver_presets_are_there():
    assert {p.stem for p in PRESETS} >= {"realsense_d4xx", "azure_kinect", "oak_d"}


@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.stem)
def test_preset_remaps_every_graph_camera_topic(path):
    preset = load_preset(str(path))
    assert set(preset["remappings"]) == set(GRAPH_CAMERA_TOPICS) == SEGMENTATION_CAMERA_TOPICS
    assert all(topic.startswith("/") for topic in preset["remappings"].values())
    options = node_options(preset, "segmentation")
    assert options["params"]["camera_frame"] == preset["camera_frame_id"]  # the driver's optical frame
    assert options["params"]["camera_pose_source"] == "estimate"
    assert options["params"]["image_reliability"] == "best_effort"
    assert node_options(preset, "reconstruction") == {"params": {}, "remaps": {}}
    assert node_options(None, "segmentation") == {}


def test_installed_presets_load_by_name():
    for name in ("realsense_d4xx", "azure_kinect", "oak_d"):
        assert load_preset(name)["remappings"]["camera/depth/image_raw"].endswith("image_raw")


def test_unknown_or_malformed_preset_is_refused(tmp_path):
    with pytest.raises(PresetError, match="not found.*realsense_d4xx"):
        load_preset("no_such_camera")
    bad = tmp_path / "bad.yaml"
    bad.write_text("camera:\n  remappings:\n    camera/rgb: /x\n")
    with pytest.raises(PresetError, match="remappings must map graph topics"):
        load_preset(str(bad))
    bad.write_text("camera:\n  remappings: {camera/camera_info: /x}\n  parameters: {segmentaton: {}}\n")
    with pytest.raises(PresetError, match="keyed by graph node"):
        load_preset(str(bad))
    bad.write_text("camera:\n  remappings: {camera/camera_info: /x}\n  encodings: {depth: 16UC1}\n")
    with pytest.raises(PresetError, match="unknown keys.*encodings"):  # a field no code would read
        load_preset(str(bad))


@pytest.mark.slow
@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.stem)
def test_segmentation_node_starts_with_the_preset(path, tmp_path):
    if not node_built("segmentation"):
        pytest.fail("segmentation_node is not installed: run make setup (colcon build)")
    use_private_domain()
    with Graph(tmp_path) as graph:
        process = graph.start("segmentation", **node_options(load_preset(str(path)), "segmentation"))
        deadline = time.monotonic() + 20.0
        while "ready" not in process.log() and process.alive() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert "camera pose from estimate" in process.log(), process.log()
        for graph_topic, driver_topic in load_preset(str(path))["remappings"].items():
            assert f"{graph_topic}:={driver_topic}" in process.cmd
