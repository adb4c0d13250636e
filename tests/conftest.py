import pytest
import rclpy

from arm_ros.common import use_private_domain


@pytest.fixture(scope="session", autouse=True)
def isolated_ros_domain():
    """Each test session talks on its own DDS domain so parallel runs never cross."""
    use_private_domain()
    yield


@pytest.fixture
def ros_node():
    rclpy.init()
    node = rclpy.create_node("integration_probe")
    yield node
    node.destroy_node()
    rclpy.try_shutdown()
