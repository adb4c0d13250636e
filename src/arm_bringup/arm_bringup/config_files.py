"""The node parameter files in config/, rendered from each node's config dataclass (arm_core.settings).

    python -m arm_bringup.config_files config/          # write the four files
    python -m arm_bringup.config_files config/ --check  # exit 1 when a file differs from its dataclass

Each file holds the node's parameters (the settings marked as parameters) with their defaults, each
commented with its description and range: the one source is the dataclass.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys

from arm_core.settings import parameters_of
from arm_planner.node_config import PlanNodeConfig
from arm_reconstruction.node_config import ReconstructionNodeConfig
from arm_segmentation.node_config import SegmentationNodeConfig
from arm_sim.node_config import SimNodeConfig

# graph key (arm_ros.processes.NODES) -> (node name, its config dataclass)
NODE_CONFIGS = {
    "sim": ("sim_node", SimNodeConfig),
    "segmentation": ("segmentation_node", SegmentationNodeConfig),
    "reconstruction": ("reconstruction_node", ReconstructionNodeConfig),
    "planner": ("plan_node", PlanNodeConfig),
}
PACKAGES = {"sim_node": "arm_sim", "segmentation_node": "arm_segmentation",
            "reconstruction_node": "arm_reconstruction", "plan_node": "arm_planner"}  # fmt: skip


def parameter_names(key: str) -> list[str]:
    """The parameters the node of a graph key declares."""
    return [s.name for s in parameters_of(NODE_CONFIGS[key][1]())]


def yaml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a YAML string
    if isinstance(value, list):
        return "[" + ", ".join(yaml_value(v) for v in value) + "]"
    return repr(value)


def render(node_name: str, config) -> str:
    lines = [
        f"# Parameters of {PACKAGES[node_name]} {node_name}, rendered from its config dataclass by",
        "#   python -m arm_bringup.config_files config/   (do not edit by hand: edit the dataclass)",
        f"# Use: ros2 run {PACKAGES[node_name]} {node_name} --ros-args --params-file config/{node_name}.yaml",
        f"{node_name}:",
        "  ros__parameters:",
    ]
    for s in parameters_of(config):
        bounds = f" [{s.low}, {s.high}]" if s.low is not None else ""
        choices = f" ({' | '.join(s.choices)})" if s.choices else ""
        lines.append(f"    # {s.description}{choices}{bounds}")
        lines.append(f"    {s.name}: {yaml_value(s.value)}")
    return "\n".join(lines) + "\n"


def rendered_files() -> dict[str, str]:
    """file name -> text of every node's parameter file."""
    return {f"{name}.yaml": render(name, config_class()) for name, config_class in NODE_CONFIGS.values()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("folder", type=pathlib.Path, help="the config folder (config/ at the top of the repository)")
    parser.add_argument("--check", action="store_true", help="only compare; exit 1 when a file differs")
    args = parser.parse_args(argv)
    stale = []
    for name, text in rendered_files().items():
        path = args.folder / name
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(str(path))
        else:
            path.write_text(text)
            print(f"wrote {path}")
    if stale:
        print(
            f"differ from their dataclasses: {', '.join(stale)}; run python -m arm_bringup.config_files {args.folder}"
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
