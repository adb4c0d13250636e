"""The shipped RViz configuration shows what the graph publishes: every display's topic is one a
node publishes, with that publisher's durability (latched meshes, sensor-data images and clouds)."""

import pathlib
import re

import yaml

SRC = pathlib.Path(__file__).resolve().parents[2]
RVIZ = SRC / "arm_bringup" / "rviz" / "arm.rviz"


def _published_topics() -> dict[str, str]:
    """topic -> 'latched' or 'volatile' for every create_publisher in the nodes' sources."""
    topics = {}
    for path in SRC.glob("*/arm_*/*.py"):
        for name, qos in re.findall(r'create_publisher\(\s*\w+,\s*"([^"]+)",\s*([^)\n]*)', path.read_text()):
            topics["/" + name.lstrip("/")] = "latched" if "latched" in qos else "volatile"
    return topics


def test_every_display_shows_a_topic_the_graph_publishes_with_its_durability():
    config = yaml.safe_load(RVIZ.read_text())
    displays = config["Visualization Manager"]["Displays"]
    published = _published_topics()
    shown = [d for d in displays if "Topic" in d]
    assert {d["Class"].split("/")[-1] for d in shown} >= {"Image", "PointCloud2", "MarkerArray"}
    for display in shown:
        topic = display["Topic"]["Value"]
        assert topic in published or topic.startswith("/camera/"), f"{display['Name']}: {topic} is published by no node"
        if topic in published:
            latched = display["Topic"]["Durability Policy"] == "Transient Local"
            assert latched == (published[topic] == "latched"), f"{display['Name']}: durability of {topic}"
    assert any(d["Class"].endswith("/TF") for d in displays)
