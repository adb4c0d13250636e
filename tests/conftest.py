import os
import random

import pytest
import rclpy


@pytest.fixture(scope="session", autouse=True)
def isolated_ros_domain():
    """Each test session talks on its own DDS domain so parallel runs never cross."""
    os.environ.setdefault("ROS_DOMAIN_ID", str(random.randint(100, 200)))
    os.environ.setdefault("ROS_LOCALHOST_ONLY", "1")
    yield


@pytest.fixture
def ros_node():
    rclpy.init()
    node = rclpy.create_node("integration_probe")
    yield node
    node.destroy_node()
    rclpy.try_shutdown()
