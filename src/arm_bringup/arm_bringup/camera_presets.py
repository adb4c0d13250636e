"""Camera presets: how to plug a real RGB-D driver into the graph instead of the simulator.

ROS parameter files cannot carry remappings, so a preset is its own small YAML file,
config/cameras/<name>.yaml (installed to share/arm_bringup/config/cameras):

    camera:
      driver: realsense2_camera                 # the driver package, for people
      camera_frame_id: camera_color_optical_frame  # the driver's optical frame: segmentation's camera_frame
      remappings:                               # graph topic: driver topic
        camera/color/image_raw: /camera/camera/color/image_raw
        camera/depth/image_raw: /camera/camera/aligned_depth_to_color/image_raw
        camera/camera_info: /camera/camera/color/camera_info
      parameters:                               # per graph node (bringup's keys): name: value
        segmentation: {camera_pose_source: estimate, image_reliability: best_effort}

Any top-level key but these is refused. camera_frame_id becomes segmentation_node's `camera_frame`
(the frame /tf lookups and the estimated `table` frame hang from). The remappings go to the nodes that
subscribe to the camera (segmentation); `bringup --camera NAME`
passes them as `-r` and the parameters as `-p` after the node's parameter file
(arm_ros.processes.NodeProcess), and the launch file's `camera:=NAME` gives them to launch_ros's Node
as remappings and parameters. With a preset the simulator is not started.
"""

import pathlib

import yaml
from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

GRAPH_CAMERA_TOPICS = ("camera/color/image_raw", "camera/depth/image_raw", "camera/camera_info")
CAMERA_NODES = ("segmentation",)  # graph nodes that subscribe to the camera topics
PRESET_KEYS = ("driver", "camera_frame_id", "remappings", "parameters")
NODE_KEYS = ("segmentation", "reconstruction", "planner")


class PresetError(ValueError):
    """A camera preset that is missing or malformed."""


def presets_dir() -> pathlib.Path | None:
    try:
        return pathlib.Path(get_package_share_directory("arm_bringup")) / "config" / "cameras"
    except PackageNotFoundError:
        return None


def preset_path(name: str) -> pathlib.Path:
    """A preset name (installed config/cameras/<name>.yaml) or a path to a preset file."""
    path = pathlib.Path(name)
    if path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        candidates = [path]
    else:
        folder = presets_dir()
        candidates = [folder / f"{name}.yaml"] if folder is not None else []
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    folder = presets_dir()
    known = sorted(p.stem for p in folder.glob("*.yaml")) if folder is not None and folder.is_dir() else []
    raise PresetError(f"camera preset '{name}' not found (installed presets: {', '.join(known) or 'none'})")


def load_preset(name: str) -> dict:
    """The validated `camera` mapping of a preset; raises PresetError with the reason."""
    path = preset_path(name)
    try:
        camera = (yaml.safe_load(path.read_text()) or {}).get("camera")
    except (yaml.YAMLError, AttributeError) as error:
        raise PresetError(f"{path}: not a preset ({error})") from error
    if not isinstance(camera, dict):
        raise PresetError(f"{path}: no top-level 'camera' mapping")
    unknown_keys = sorted(set(camera) - set(PRESET_KEYS))
    if unknown_keys:
        raise PresetError(f"{path}: unknown keys {unknown_keys}; a preset has {list(PRESET_KEYS)}")
    if not isinstance(camera.get("camera_frame_id", ""), str):
        raise PresetError(f"{path}: camera_frame_id must be a frame name")
    remappings = camera.get("remappings") or {}
    unknown = sorted(set(remappings) - set(GRAPH_CAMERA_TOPICS))
    if unknown or not remappings:
        raise PresetError(f"{path}: remappings must map graph topics {GRAPH_CAMERA_TOPICS}, got {sorted(remappings)}")
    if not all(isinstance(t, str) and t for t in remappings.values()):
        raise PresetError(f"{path}: every remapping needs a driver topic name")
    parameters = camera.get("parameters") or {}
    if not isinstance(parameters, dict) or set(parameters) - set(NODE_KEYS):
        raise PresetError(f"{path}: parameters must be keyed by graph node ({', '.join(NODE_KEYS)})")
    from arm_bringup.config_files import parameter_names  # imports every node's core: only when a preset is read

    for key, values in parameters.items():
        if not isinstance(values, dict):
            raise PresetError(f"{path}: parameters of {key} must be a mapping of name: value")
        unknown = sorted(set(values) - set(parameter_names(key)))
        if unknown:
            raise PresetError(f"{path}: {key} has no parameters {unknown}; it has {parameter_names(key)}")
    return {**camera, "remappings": dict(remappings), "parameters": parameters, "path": str(path)}


def node_remappings(preset: dict, key: str) -> dict[str, str]:
    return dict(preset["remappings"]) if key in CAMERA_NODES else {}


def node_parameters(preset: dict, key: str) -> dict:
    """A node's parameters from a preset: its `parameters` entry, and for the camera's nodes the
    optical frame (camera_frame_id) unless the entry sets camera_frame itself."""
    parameters = dict(preset["parameters"].get(key) or {})
    if key in CAMERA_NODES and preset.get("camera_frame_id"):
        parameters.setdefault("camera_frame", preset["camera_frame_id"])
    return parameters


def node_options(preset: dict | None, key: str) -> dict:
    """NodeProcess keyword arguments (params, remaps) of a preset for one graph node; {} without one."""
    if preset is None:
        return {}
    return {"params": node_parameters(preset, key), "remaps": node_remappings(preset, key)}
