import contextlib
import os
import threading
import time

import numpy as np
import pytest
import rclpy
import torch
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.action import ActionClient, ActionServer
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

from arm_core.camera import look_at
from arm_interfaces.action import Manipulate
from arm_interfaces.msg import ReconstructedObjectArray, SegmentedFrame
from arm_reconstruction.checkpoint import save_checkpoint
from arm_reconstruction.grid import voxelize_mesh
from arm_reconstruction.messages import (
    markers_msg,
    object_from_msg,
    object_to_msg,
    objects_to_msg,
)
from arm_reconstruction.network import build_model
from arm_reconstruction.pipeline import ReconstructionSettings, Reconstructor
from arm_reconstruction.reconstruction_node import ReconstructionNode
from arm_ros.common import latched_qos
from arm_ros.conversions import ConversionError
from arm_ros.conversions.frames import frame_from_msg, segmented_frame_msg
from arm_ros.conversions.poses import pose_to_matrix
from arm_ros.tf import TfListener
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SimWorld

torch.set_num_threads(2)


@pytest.fixture(scope="module")
def sim():
    rng = np.random.default_rng(11)
    scene = cluttered_scene(object_pool(split="train", seed=0), rng, n_objects=4)
    world = SimWorld(scene, robot_arm=False, width=160, height=120)
    centre = np.mean([o.T_world_object[:3, 3] for o in scene.objects], axis=0)
    frame = world.render(look_at(centre + (0.5, 0.15, 0.4), centre), rng=rng)
    world.close()
    return scene, frame


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """An untrained network: the node's plumbing, not reconstruction accuracy."""
    path = tmp_path_factory.mktemp("ckpt") / "arm.pt"
    torch.manual_seed(0)
    save_checkpoint(path, build_model("arm", 16), {}, {"note": "untrained"})
    return path


def frame_msg(frame):
    return segmented_frame_msg(frame, Header(frame_id="cam"))


def test_messages_round_trip(sim, checkpoint):
    scene, frame = sim
    msg = frame_msg(frame)
    data = frame_from_msg(msg)
    np.testing.assert_array_equal(data.labels, frame.labels)
    np.testing.assert_allclose(data.depth_m, frame.depth_m)
    np.testing.assert_allclose(data.T_world_camera, frame.T_world_camera, atol=1e-9)
    assert data.instance_ids == sorted(int(i) for i in np.unique(frame.labels) if i > 0)
    reconstructor = Reconstructor(ReconstructionSettings(checkpoint_path=str(checkpoint)))
    grids = reconstructor.grids(frame.depth_m, frame.K, frame.T_world_camera, frame.labels)
    pairs = zip(grids.object_ids, grids.frames, strict=True)
    truth = np.stack([voxelize_mesh(scene.objects[i - 1].world_mesh(), f) for i, f in pairs]).astype(np.float32)
    objects = reconstructor.build_objects(grids, truth, frame.depth_m, frame.labels, frame.K, frame.T_world_camera)
    ok = [o for o in objects if o.ok]
    assert ok
    back = object_from_msg(object_to_msg(ok[0]))
    np.testing.assert_allclose(back.T_world_object, ok[0].T_world_object, atol=1e-9)
    np.testing.assert_allclose(back.mesh.vertices, ok[0].mesh.vertices, atol=1e-12)
    assert len(back.convex_parts) == len(ok[0].convex_parts) and back.grid == ok[0].grid
    array = objects_to_msg(objects, Header(frame_id="world"), 0.0)
    assert [o.id for o in array.objects] == [o.id for o in ok]
    ok[0].vertex_colours = np.tile(np.array([200, 100, 0], np.uint8), (len(ok[0].mesh.vertices), 1))
    markers = markers_msg(objects, Header(frame_id="world"))
    assert markers.markers[0].action == Marker.DELETEALL and len(markers.markers) == 1 + len(ok)
    first = next(m for m in markers.markers if m.id == ok[0].id)
    assert len(first.points) == len(first.colors) == 3 * len(ok[0].mesh.faces)  # coloured per vertex
    assert first.colors[0].r == pytest.approx(200 / 255) and first.colors[0].a == pytest.approx(0.8)


def test_malformed_frames_raise_conversion_errors(sim):
    _, frame = sim
    msg = frame_msg(frame)
    msg.depth.encoding = "rgb8"
    with pytest.raises(ConversionError):
        frame_from_msg(msg)
    msg = frame_msg(frame)
    msg.camera_pose.position.x = float("nan")
    with pytest.raises(ConversionError):
        frame_from_msg(msg)
    msg = frame_msg(frame)
    msg.labels.data = msg.labels.data[:10]
    with pytest.raises(ConversionError):
        frame_from_msg(msg)


@pytest.fixture
def ros_context():
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=100 + os.getpid() % 100)
    yield context
    rclpy.try_shutdown(context=context)


def spin_until(executor, condition, timeout_s=60.0):
    deadline = time.monotonic() + timeout_s
    while not condition() and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    return condition()


@contextlib.contextmanager
def node_and_client(context, checkpoint, **params):
    """A ReconstructionNode on `checkpoint` (in-process: niceness left alone) with `params`, a client
    node and one executor spinning both; torn down on exit."""
    overrides = [Parameter("checkpoint_path", value=str(checkpoint)), Parameter("cpu_niceness", value=0)]
    overrides += [Parameter(name, value=value) for name, value in params.items()]
    node = ReconstructionNode(context=context, parameter_overrides=overrides)
    client = rclpy.create_node("reconstruction_test_client", context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    executor.add_node(client)
    try:
        yield node, client, executor
    finally:
        node.close()
        executor.shutdown()
        node.destroy_node()
        client.destroy_node()


def test_node_publishes_latched_meshes_and_survives_bad_frames(sim, checkpoint, ros_context):
    _, frame = sim
    # an untrained network predicts ~0.1 everywhere: a low threshold makes it emit solid grids,
    # which exercises meshing, intersection removal, decomposition and publishing
    with node_and_client(ros_context, checkpoint, threshold=0.05) as (node, client, executor):
        diagnostics = []
        client.create_subscription(DiagnosticArray, "diagnostics", diagnostics.append, 10)
        tf = TfListener(client)
        publisher = client.create_publisher(SegmentedFrame, "arm/segmented_frame", 10)
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10)
        bad = frame_msg(frame)
        bad.camera_pose.orientation.w = float("nan")
        publisher.publish(bad)
        assert spin_until(executor, lambda: node.rejected == 1, 20)
        publisher.publish(frame_msg(frame))
        assert spin_until(executor, lambda: node.processed == 1, 120)
        arrays, markers = [], []
        client.create_subscription(ReconstructedObjectArray, "arm/meshes", arrays.append, latched_qos())
        client.create_subscription(MarkerArray, "arm/meshes/markers", markers.append, latched_qos())
        assert spin_until(executor, lambda: arrays and markers, 20), "late subscriber gets the scene"

        def status_after_the_frame():
            values = [{kv.key: kv.value for kv in d.status[0].values} for d in diagnostics]
            return next((v for v in reversed(values) if v.get("frames_processed") == "1"), None)

        assert spin_until(executor, lambda: status_after_the_frame() is not None, 20)
        array = arrays[0]
        ids = sorted(int(i) for i in np.unique(frame.labels) if i > 0)
        assert [o.id for o in array.objects] == ids and array.header.frame_id == "world"
        for obj in array.objects:
            assert len(obj.mesh.triangles) > 0 and 1 <= len(obj.convex_parts) <= 8 and obj.method == "arm"
            assert obj.grid.resolution == 16
        assert len(markers[0].markers) == 1 + len(ids)
        # each object's frame on /tf: object_<id> in the world frame, at the mesh's pose
        assert spin_until(executor, lambda: all(tf.lookup("world", f"object_{i}") is not None for i in ids), 10)
        for obj in array.objects:
            assert np.allclose(tf.lookup("world", f"object_{obj.id}"), pose_to_matrix(obj.pose), atol=1e-6)
        values = status_after_the_frame()
        assert {"grid_ms", "network_ms", "decomposition_ms", "frame_to_meshes_ms", "frames_dropped"} <= set(values)
        assert node.received == 2 and node.rejected == 1


def test_max_rate_spaces_reconstructions_and_keeps_the_newest_frame(sim, checkpoint, ros_context):
    _, frame = sim
    # A 5 s spacing: the three frames below arrive within it even on a loaded machine.
    with node_and_client(ros_context, checkpoint, max_rate_hz=0.2) as (node, client, executor):
        publisher = client.create_publisher(SegmentedFrame, "arm/segmented_frame", 10)
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10)
        publisher.publish(frame_msg(frame))
        assert spin_until(executor, lambda: node.processed == 1, 120)
        first_start = node.last_start_s
        for _ in range(3):  # arrive within the 5 s: the last one is reconstructed, the others dropped
            publisher.publish(frame_msg(frame))
            executor.spin_once(timeout_sec=0.01)
        assert spin_until(executor, lambda: node.processed == 2, 120)
        assert node.last_start_s - first_start >= 4.99
        assert node.received == 4 and node.dropped == 2


def test_missing_checkpoint_is_a_configuration_error(ros_context, tmp_path):
    with pytest.raises(ValueError, match="checkpoint"):
        ReconstructionNode(
            context=ros_context,
            parameter_overrides=[
                Parameter("checkpoint_path", value=str(tmp_path / "x.pt")),
                Parameter("cpu_niceness", value=0),
            ],
        )


@pytest.mark.slow
@pytest.mark.parametrize("width, height", [(848, 480), (1280, 720)])
def test_node_reconstructs_frames_of_real_camera_resolutions(checkpoint, ros_context, width, height):
    rng = np.random.default_rng(5)
    scene = cluttered_scene(object_pool(split="train", seed=0), rng, n_objects=3)
    world = SimWorld(scene, robot_arm=False, width=width, height=height)
    centre = np.mean([o.T_world_object[:3, 3] for o in scene.objects], axis=0)
    frame = world.render(look_at(centre + (0.5, 0.15, 0.4), centre), rng=rng)
    world.close()
    assert frame.depth_m.shape == (height, width)
    msg = frame_msg(frame)
    node = ReconstructionNode(
        context=ros_context,
        parameter_overrides=[
            Parameter("checkpoint_path", value=str(checkpoint)),
            Parameter("threshold", value=0.05),
            Parameter("cpu_niceness", value=0),
        ],
    )
    try:
        node.process(msg)
        assert node.processed == 1 and node.rejected == 0
        assert node._stage_values["objects"] == len(set(np.unique(frame.labels)) - {0})
    finally:
        node.close()
        node.destroy_node()


def test_frames_wait_while_the_planner_serves_a_goal(sim, checkpoint, ros_context):
    """A real Manipulate action server holds a goal open: the frame sent meanwhile is reconstructed
    only once the goal ends, a second frame sent meanwhile replaces it, and a frame under way is
    abandoned."""
    _, frame = sim
    release = threading.Event()

    def execute(goal_handle):
        release.wait(60.0)
        goal_handle.succeed()
        return Manipulate.Result(success=True)

    with node_and_client(ros_context, checkpoint) as (node, client, executor):
        server = ActionServer(client, Manipulate, "arm/manipulate", execute)
        action_client = ActionClient(client, Manipulate, "arm/manipulate")
        spinner = MultiThreadedExecutor(context=ros_context)  # the server's execute blocks: spin it apart
        spinner.add_node(client)
        executor.remove_node(client)
        threading.Thread(target=spinner.spin, daemon=True).start()
        try:
            publisher = client.create_publisher(SegmentedFrame, "arm/segmented_frame", 10)
            assert action_client.wait_for_server(timeout_sec=10.0)
            action_client.send_goal_async(Manipulate.Goal(task=0, target_id=1))
            assert spin_until(executor, lambda: node.goals.seconds_left() > 0, 20)
            assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10)
            for count in (1, 2):
                publisher.publish(frame_msg(frame))
                assert spin_until(executor, lambda: node.received == count, 20)  # noqa: B023
            spin_until(executor, lambda: node.processed > 0, 3.0)
            assert node.processed == 0 and node.dropped == 1 and node.goals.pauses == 1
            node.process(frame_msg(frame))  # a frame already under way when the goal came: abandoned
            assert node.preempted == 1 and node.processed == 0
            release.set()
            assert spin_until(executor, lambda: node.processed == 1, 120)
            assert node.goals.seconds_left() == 0.0
        finally:
            release.set()
            spinner.shutdown()
            server.destroy()
            action_client.destroy()
