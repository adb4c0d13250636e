"""Robustness harness shared by tests/robustness and bench_robustness: node processes with their
logs and memory, an in-process DDS probe, error-log analysis, validators of what the nodes publish,
input frames rendered by the simulator and a camera bag for load runs."""

from __future__ import annotations

import dataclasses
import os
import pathlib
import re
import threading
import time
from collections import deque

import numpy as np
from geometry_msgs.msg import PoseStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from arm_reconstruction.checkpoint import default_checkpoint_path
from arm_ros.conversions import ConversionError
from arm_ros.conversions.frames import segmented_frame_msg as frame_to_segmented_msg
from arm_ros.conversions.images import K_from_camera_info, camera_info_from_K, image_to_numpy, numpy_to_image
from arm_ros.conversions.meshes import msg_to_mesh
from arm_ros.conversions.poses import matrix_to_pose, pose_to_matrix
from arm_ros.processes import NODES, NodeProcess, config_file, executable, node_built, rss_mb  # noqa: F401
from arm_sim import robot

ROOT = pathlib.Path(os.environ.get("ARM_ROOT") or pathlib.Path.cwd())
NODE_NAMES = {
    "sim": "sim_node",
    "segmentation": "segmentation_node",
    "reconstruction": "reconstruction_node",
    "planner": "plan_node",
    "record": "bag_recorder",
    "replay": "bag_replayer",
}
SHIPPED_CHECKPOINT = default_checkpoint_path("arm")
CAMERA_TOPICS = ("camera/color/image_raw", "camera/depth/image_raw", "camera/camera_info", "camera/pose")


def reconstruction_checkpoint() -> pathlib.Path | None:
    """The checkpoint the reconstruction node runs with in robustness runs: ARM_ROBUSTNESS_CHECKPOINT
    if set, else the shipped one; None when neither exists."""
    override = os.environ.get("ARM_ROBUSTNESS_CHECKPOINT")
    path = pathlib.Path(override) if override else SHIPPED_CHECKPOINT
    return path if path.exists() else None


def reconstruction_params() -> dict | None:
    """Parameters of the reconstruction node in robustness runs: its checkpoint (see
    reconstruction_checkpoint) plus ARM_ROBUSTNESS_RECON_PARAMS="name:=value ..."; None without a
    checkpoint."""
    checkpoint = reconstruction_checkpoint()
    if checkpoint is None:
        return None
    params = {"checkpoint_path": str(checkpoint)}
    for item in os.environ.get("ARM_ROBUSTNESS_RECON_PARAMS", "").split():
        name, value = item.split(":=", 1)
        try:
            params[name] = int(value) if value.lstrip("-").isdigit() else float(value)
        except ValueError:
            params[name] = value
    return params


# --- logs ---------------------------------------------------------------------------------------
ERROR_LINE = re.compile(
    r"^\[ERROR\] \[(?P<time>[\d.]+)\] \[(?P<node>[^\]]+)\]: (?P<text>.*?)"
    r"(?: \[(?P<cause>[^\[\]]+), seen (?P<seen>\d+)x\])?$",
    re.M,
)


@dataclasses.dataclass
class ErrorLine:
    time_s: float
    node: str
    text: str
    cause: str
    seen: int


def error_lines(log_text: str) -> list[ErrorLine]:
    return [
        ErrorLine(float(m["time"]), m["node"], m["text"], m["cause"] or m["text"], int(m["seen"] or 1))
        for m in ERROR_LINE.finditer(log_text)
    ]


def rate_limit_violations(lines: list[ErrorLine], period_s: float = 5.0) -> list[str]:
    """Causes logged twice within period_s (a burst of one cause must give one line per period)."""
    last: dict[str, float] = {}
    violations = []
    for line in lines:
        if line.cause in last and line.time_s - last[line.cause] < 0.9 * period_s:
            violations.append(f"{line.cause!r} logged again after {line.time_s - last[line.cause]:.2f} s")
        last[line.cause] = line.time_s
    return violations


def tracebacks(log_text: str) -> list[str]:
    """The last line of every Python traceback in a log."""
    found = []
    lines = log_text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("Traceback (most recent call last)"):
            tail = next((t for t in lines[i + 1 :] if t and not t.startswith((" ", "\t"))), "?")
            found.append(tail)
    return found


# --- DDS probe ----------------------------------------------------------------------------------
class Probe:
    """An rclpy node in its own context, spun by a background thread: publishers for inputs,
    recorders of outputs and of /diagnostics."""

    def __init__(self, name: str = "robustness_probe"):
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self._rclpy = rclpy
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self.diagnostics: dict[str, dict[str, str]] = {}
        self.diagnostics_history: dict[str, deque] = {}
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        from arm_ros.common import spin_until_shutdown

        spin_until_shutdown(self.executor)

    def publisher(self, msg_type, topic: str, qos=10):
        return self.node.create_publisher(msg_type, topic, qos)

    def record(self, msg_type, topic: str, qos=10, keep: int | None = None, on_message=None):
        """Messages received on topic, in a list (or a deque of the last `keep`), with their arrival
        times (time.monotonic) in the parallel `.times` attribute, the running count in `.total` and
        the rclpy subscription in `.subscription`."""
        store = _Recorded(keep)

        def callback(msg):
            with self.lock:
                store.append(msg)
                store.times.append(time.monotonic())
                store.total += 1
            if on_message is not None:
                on_message(msg)

        store.subscription = self.node.create_subscription(msg_type, topic, callback, qos)
        return store

    def watch_diagnostics(self, history: int = 2000) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        def callback(msg):
            with self.lock:
                for status in msg.status:
                    values = {kv.key: kv.value for kv in status.values}
                    values["_level"] = str(
                        int.from_bytes(status.level, "little") if isinstance(status.level, bytes) else int(status.level)
                    )
                    values["_message"] = status.message
                    values["_received_s"] = str(time.monotonic())
                    self.diagnostics[status.name] = values
                    self.diagnostics_history.setdefault(status.name, deque(maxlen=history)).append(values)

        self.node.create_subscription(DiagnosticArray, "/diagnostics", callback, 100)

    def diagnostic(self, node_name: str) -> dict[str, str]:
        """Latest diagnostics values of the status whose name starts with node_name."""
        with self.lock:
            for name, values in self.diagnostics.items():
                if name.startswith(node_name + ":"):
                    return dict(values)
        return {}

    def diagnostic_number(self, node_name: str, key: str, default: float = float("nan")) -> float:
        try:
            return float(self.diagnostic(node_name).get(key, default))
        except ValueError:
            return default

    def in_executor(self, fn, timeout_s: float = 10.0):
        """Run fn() on the executor thread and return its value. rclpy's ActionClient is not thread
        safe: a goal or result response taken between send_*_request and the registration of its
        future is dropped ('Ignoring unexpected goal response'), so requests go out from there."""
        done, out = threading.Event(), {}

        def task():
            try:
                out["value"] = fn()
            except Exception as error:  # handed back to the caller
                out["error"] = error
            finally:
                done.set()

        self.executor.create_task(task)
        if not done.wait(timeout_s):
            raise TimeoutError("the probe's executor did not run the task")
        if "error" in out:
            raise out["error"]
        return out["value"]

    def wait_until(self, predicate, timeout_s: float, poll_s: float = 0.05) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if predicate():
                return True
            time.sleep(poll_s)
        return bool(predicate())

    def wait_for_subscribers(self, publishers, timeout_s: float = 30.0) -> bool:
        return self.wait_until(lambda: all(p.get_subscription_count() > 0 for p in publishers), timeout_s)

    def close(self) -> None:
        self._rclpy.try_shutdown(context=self.context)  # the spin thread returns quietly
        self._thread.join(timeout=2.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()


class _Recorded(deque):
    def __init__(self, keep):
        super().__init__(maxlen=keep)
        self.times = deque(maxlen=keep)
        self.total = 0
        self.subscription = None


def stamp_of(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def header_at(stamp_s: float, frame_id: str) -> Header:
    header = Header(frame_id=frame_id)
    ns = int(round(stamp_s * 1e9))
    header.stamp.sec, header.stamp.nanosec = ns // 10**9, ns % 10**9
    return header


# --- validators: what a node publishes must be well formed ---------------------------------------
def segmented_frame_problems(msg) -> list[str]:
    problems = []
    try:
        depth = image_to_numpy(msg.depth)
        labels = image_to_numpy(msg.labels)
        if msg.depth.encoding != "32FC1" or msg.labels.encoding != "16UC1":
            problems.append(f"encodings depth={msg.depth.encoding} labels={msg.labels.encoding}")
        if depth.shape != labels.shape:
            problems.append(f"depth {depth.shape} vs labels {labels.shape}")
        if msg.rgb.height and image_to_numpy(msg.rgb).shape[:2] != depth.shape:
            problems.append("rgb and depth differ in size")
        if np.any(np.isinf(depth)) or np.any(depth < 0):
            problems.append("depth has inf or negative values")
        ids = sorted(int(i) for i in np.unique(labels) if i > 0)
        if ids != [int(i) for i in msg.instance_ids]:
            problems.append(f"instance_ids {list(msg.instance_ids)} vs labels {ids}")
        K_from_camera_info(msg.camera_info)
        pose_to_matrix(msg.camera_pose)
        if not msg.world_frame_id:
            problems.append("no world_frame_id")
    except ConversionError as error:
        problems.append(str(error))
    return problems


def mesh_array_problems(msg) -> list[str]:
    problems = []
    if not np.isfinite(msg.table_height_m):
        problems.append("table_height_m not finite")
    ids = [int(o.id) for o in msg.objects]
    if ids != sorted(set(ids)):
        problems.append(f"ids not unique ascending: {ids}")
    for obj in msg.objects:
        try:
            pose_to_matrix(obj.pose)
            vertices, faces = msg_to_mesh(obj.mesh)
            if len(faces) == 0:
                problems.append(f"object {obj.id}: empty mesh")
            for part in obj.convex_parts:
                msg_to_mesh(part)
        except ConversionError as error:
            problems.append(f"object {obj.id}: {error}")
    return problems


def joint_state_problems(msg) -> list[str]:
    positions = np.asarray(msg.position, dtype=np.float64)
    problems = []
    if len(positions) != len(msg.name):
        problems.append(f"{len(msg.name)} names, {len(positions)} positions")
    if not np.all(np.isfinite(positions)):
        problems.append("non-finite positions")
    else:
        lo, hi = np.asarray(robot.JOINT_LIMITS, dtype=np.float64).reshape(-1, 2)[:7].T
        q = positions[:7]
        if len(q) == 7 and (np.any(q < lo - 0.05) or np.any(q > hi + 0.05)):
            problems.append("joint positions outside the limits")
    return problems


def trajectory_problems(msg) -> list[str]:
    times = np.array([p.time_from_start.sec + 1e-9 * p.time_from_start.nanosec for p in msg.points])
    positions = [np.asarray(p.positions, dtype=np.float64) for p in msg.points]
    problems = []
    if len(times) == 0:
        problems.append("no points")
    if len(times) > 1 and np.any(np.diff(times) <= 0):
        problems.append("time_from_start does not increase")
    if any(len(p) != len(msg.joint_names) or not np.all(np.isfinite(p)) for p in positions):
        problems.append("points with wrong sizes or non-finite positions")
    return problems


# --- inputs ---------------------------------------------------------------------------------------
CAMERA_EYE = (0.7, 0.0, 0.5)
CAMERA_TARGET = (0.0, 0.0, 0.05)


def render_frames(
    n_objects: int, width: int = 320, height: int = 240, seed: int = 0, count: int = 1, settle_s: float = 1.0
):
    """`count` noisy renders of one seeded, settled cluttered scene (no robot), as RgbdFrames."""
    from arm_core.camera import look_at
    from arm_sim.objects import object_pool
    from arm_sim.views import BenchmarkScene

    rng = np.random.default_rng(seed)
    pool = object_pool(split="heldout", seed=seed) if n_objects else None
    options = dict(scale_range=(0.5, 1.2), drop_std_m=0.08 + 0.004 * n_objects, settle_s=settle_s)
    with BenchmarkScene(pool, rng, n_objects, with_visibility=False, width=width, height=height, **options) as views:
        T_world_camera = look_at(CAMERA_EYE, CAMERA_TARGET)
        return [views.render(T_world_camera) for _ in range(count)]


def camera_messages(
    frame, stamp_s: float, camera_frame_id: str = "camera_color_optical_frame", world_frame_id: str = "world"
) -> dict:
    """rgb, depth, camera_info and pose messages of one RgbdFrame, keyed by CAMERA_TOPICS."""
    header = header_at(stamp_s, camera_frame_id)
    h, w = frame.depth_m.shape
    return {
        "camera/color/image_raw": numpy_to_image(frame.rgb, "rgb8", header),
        "camera/depth/image_raw": numpy_to_image(frame.depth_m, "32FC1", header),
        "camera/camera_info": camera_info_from_K(frame.K, w, h, header),
        "camera/pose": PoseStamped(
            header=header_at(stamp_s, world_frame_id), pose=matrix_to_pose(frame.T_world_camera)
        ),
    }


def segmented_frame_msg(frame, stamp_s: float, labels: np.ndarray | None = None):
    """SegmentedFrame of an RgbdFrame with its simulator labels (the ground-truth segmentation)."""
    labels = frame.labels if labels is None else labels
    header = header_at(stamp_s, "camera_color_optical_frame")
    return frame_to_segmented_msg(dataclasses.replace(frame, labels=labels, world_frame_id="world"), header)


def joint_state_msg(stamp_s: float = 0.0, q=None, opening_m: float = 0.04) -> JointState:
    q = robot.HOME_Q if q is None else q
    names = list(robot.JOINT_NAMES) + [robot.FINGER_JOINT_NAMES[0]]
    return JointState(header=header_at(stamp_s, ""), name=names, position=[float(v) for v in q] + [float(opening_m)])


def write_camera_bag(path, frames, rate_hz: float, storage: str = "mcap", joint_states: bool = True) -> dict:
    """A bag of the frames as a camera at rate_hz would publish them (stamps and receive times
    k / rate_hz), with joint states at the same instants. Returns messages per topic."""
    from arm_bags.bags import write_bag

    def messages():
        for k, frame in enumerate(frames):
            stamp_s = (k + 1) / rate_hz
            t_ns = int(round(stamp_s * 1e9))
            for topic, msg in camera_messages(frame, stamp_s).items():
                yield "/" + topic, t_ns, msg
            if joint_states:
                yield "/joint_states", t_ns, joint_state_msg(stamp_s)

    return write_bag(path, messages(), storage)


def broken_bags(folder, messages, fractions=(0.5, 0.9)) -> dict[str, pathlib.Path]:
    """Bags a reader must refuse with a BagError, by name: a good bag of `messages` (topic, stamp ns,
    message) in each storage truncated to each fraction of its bytes, an empty directory, a missing
    path, random bytes named .mcap and a text file."""
    import shutil

    from arm_bags.bags import write_bag

    folder = pathlib.Path(folder)
    messages = list(messages)
    bags = {}
    for storage in ("mcap", "sqlite3"):
        good = folder / f"good_{storage}"
        write_bag(good, messages, storage)
        for fraction in fractions:
            path = folder / f"truncated_{storage}_{int(fraction * 100)}"
            shutil.copytree(good, path)
            storage_file = next(f for f in path.iterdir() if f.suffix in (".mcap", ".db3"))
            data = storage_file.read_bytes()
            storage_file.write_bytes(data[: int(len(data) * fraction)])
            bags[f"{storage} truncated to {int(fraction * 100)} %"] = path
    (folder / "empty_dir").mkdir()
    bags["empty directory"] = folder / "empty_dir"
    bags["missing path"] = folder / "does_not_exist"
    garbage = folder / "garbage.mcap"
    garbage.write_bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    bags["random bytes .mcap"] = garbage
    (folder / "notes.txt").write_text("not a bag")
    bags["text file"] = folder / "notes.txt"
    return bags


# --- parameters over the ROS parameter services ---------------------------------------------------
BUILTIN_PARAMETERS = {"use_sim_time", "start_type_description_service"}


def _call(probe, srv_type, service: str, request, timeout_s: float = 20.0):
    client = probe.node.create_client(srv_type, service)
    try:
        if not client.wait_for_service(timeout_sec=timeout_s):
            raise TimeoutError(f"service {service} not available")
        future = client.call_async(request)
        if not probe.wait_until(future.done, timeout_s):
            raise TimeoutError(f"no answer from {service}")
        return future.result()
    finally:
        probe.node.destroy_client(client)


def describe_parameters(probe, node_name: str) -> dict[str, dict]:
    """{name: {type, description, has_range, constraints, read_only}} of a running node."""
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import DescribeParameters, ListParameters

    names = list(_call(probe, ListParameters, f"/{node_name}/list_parameters", ListParameters.Request()).result.names)
    descriptors = _call(
        probe, DescribeParameters, f"/{node_name}/describe_parameters", DescribeParameters.Request(names=names)
    ).descriptors
    numeric = {ParameterType.PARAMETER_INTEGER: "integer", ParameterType.PARAMETER_DOUBLE: "double"}
    return {
        d.name: {
            "type": int(d.type),
            "numeric": int(d.type) in numeric,
            "description": d.description,
            "has_range": bool(len(d.integer_range) or len(d.floating_point_range)),
            "constraints": d.additional_constraints,
            "read_only": bool(d.read_only),
        }
        for d in descriptors
    }


def set_parameter(probe, node_name: str, name: str, value) -> tuple[bool, str]:
    """Set one parameter of a running node: (successful, reason)."""
    from rcl_interfaces.srv import SetParameters
    from rclpy.parameter import Parameter

    request = SetParameters.Request(parameters=[Parameter(name, value=value).to_parameter_msg()])
    result = _call(probe, SetParameters, f"/{node_name}/set_parameters", request).results[0]
    return bool(result.successful), result.reason


def config_keys(config_name: str, node_name: str) -> set[str]:
    """Parameter names (dotted) in config/<file> for node_name."""
    import yaml

    data = yaml.safe_load(config_file(config_name).read_text())[node_name]["ros__parameters"]

    def flatten(prefix, value):
        if isinstance(value, dict):
            for k, v in value.items():
                yield from flatten(f"{prefix}{k}.", v)
        else:
            yield prefix[:-1]

    return set(flatten("", data))


def convention_report(probe, key: str) -> dict:
    """Descriptors, ranges, config-file coverage and run-time rejection of bad values of one node."""
    node_name = NODE_NAMES[key]
    params = describe_parameters(probe, node_name)
    own = {n: p for n, p in params.items() if n not in BUILTIN_PARAMETERS}
    report = {
        "parameters": len(own),
        "without_description": sorted(n for n, p in own.items() if not p["description"]),
        "numeric_without_range": sorted(n for n, p in own.items() if p["numeric"] and not p["has_range"]),
    }
    if NODES[key][2]:
        keys = config_keys(NODES[key][2], node_name)
        report["in_config_not_declared"] = sorted(keys - set(own))
        report["declared_not_in_config"] = sorted(set(own) - keys)
    accepted = []
    for name, p in own.items():
        if p["read_only"]:
            continue
        if p["numeric"] and p["has_range"]:
            ok, _ = set_parameter(probe, node_name, name, 10**12 if p["type"] == 2 else 1e12)
            if ok:
                accepted.append(f"{name}=1e12")
        elif p["constraints"].startswith("one of:"):
            ok, _ = set_parameter(probe, node_name, name, "not-a-choice")
            if ok:
                accepted.append(f"{name}='not-a-choice'")
    report["bad_values_accepted_at_run_time"] = accepted
    return report
