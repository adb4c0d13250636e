"""The reconstruction node at real cameras' resolutions (RealSense 848x480, Azure Kinect / RealSense 1280x720)."""

import os

import numpy as np
import pytest
import rclpy
import torch
from rclpy.parameter import Parameter
from std_msgs.msg import Header

from arm_core.camera import look_at
from arm_reconstruction.checkpoint import save_checkpoint
from arm_reconstruction.messages import frame_to_msg
from arm_reconstruction.network import build_model
from arm_reconstruction.reconstruction_node import ReconstructionNode
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SimWorld

torch.set_num_threads(2)


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """An untrained network: the node's handling of the frame size, not reconstruction accuracy."""
    path = tmp_path_factory.mktemp("ckpt") / "arm.pt"
    torch.manual_seed(0)
    save_checkpoint(path, build_model("arm", 16), {}, {"note": "untrained"})
    return path


@pytest.fixture
def ros_context():
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=100 + os.getpid() % 100)
    yield context
    rclpy.try_shutdown(context=context)


@pytest.mark.slow
@pytest.mark.parametrize("width, height", [(848, 480), (1280, 720)])
def test_node_reconstructs_frames_of_driver_resolutions(checkpoint, ros_context, width, height):
    rng = np.random.default_rng(5)
    scene = cluttered_scene(object_pool(split="train", seed=0), rng, n_objects=3)
    world = SimWorld(scene, robot_arm=False, width=width, height=height)
    centre = np.mean([o.T_world_object[:3, 3] for o in scene.objects], axis=0)
    frame = world.render(look_at(centre + (0.5, 0.15, 0.4), centre), rng=rng)
    world.close()
    assert frame.depth_m.shape == (height, width)
    msg = frame_to_msg(frame.rgb, frame.depth_m, frame.K, frame.T_world_camera, frame.labels, Header(frame_id="cam"))
    node = ReconstructionNode(
        context=ros_context,
        parameter_overrides=[Parameter("checkpoint_path", value=str(checkpoint)), Parameter("threshold", value=0.05)],
    )
    try:
        node.process(msg)
        assert node.processed == 1 and node.rejected == 0
        assert node._stage_values["objects"] == len(set(np.unique(frame.labels)) - {0})
    finally:
        node.close()
        node.destroy_node()
