"""use_large_socket_buffers: Fast DDS's transports for the nodes, and an image that crosses them."""

import os
import subprocess
import sys
import textwrap

import pytest

from arm_ros.common import DDS_SOCKET_BUFFER_BYTES, use_large_socket_buffers, use_private_domain

VARIABLES = ("RMW_IMPLEMENTATION", "FASTRTPS_DEFAULT_PROFILES_FILE", "FASTDDS_DEFAULT_PROFILES_FILE")


@pytest.fixture
def clean_env(monkeypatch):
    for name in (*VARIABLES, "FASTDDS_BUILTIN_TRANSPORTS"):
        monkeypatch.delenv(name, raising=False)
    return monkeypatch


def test_unset_transports_become_udp_with_large_buffers(clean_env):
    assert use_large_socket_buffers() == f"UDPv4?sockets_size={DDS_SOCKET_BUFFER_BYTES}"
    assert os.environ["FASTDDS_BUILTIN_TRANSPORTS"] == f"UDPv4?sockets_size={DDS_SOCKET_BUFFER_BYTES}"


def test_a_named_mode_keeps_its_name_and_gains_the_buffers(clean_env):
    clean_env.setenv("FASTDDS_BUILTIN_TRANSPORTS", "LARGE_DATA")
    assert use_large_socket_buffers() == f"LARGE_DATA?sockets_size={DDS_SOCKET_BUFFER_BYTES}"


@pytest.mark.parametrize(
    "name, value",
    [
        ("FASTDDS_BUILTIN_TRANSPORTS", "UDPv4?sockets_size=1048576"),
        ("FASTRTPS_DEFAULT_PROFILES_FILE", "/etc/fastdds.xml"),
        ("FASTDDS_DEFAULT_PROFILES_FILE", "/etc/fastdds.xml"),
        ("RMW_IMPLEMENTATION", "rmw_cyclonedds_cpp"),
    ],
)
def test_a_users_own_dds_configuration_is_left_alone(clean_env, name, value):
    clean_env.setenv(name, value)
    assert use_large_socket_buffers() is None
    assert os.environ.get("FASTDDS_BUILTIN_TRANSPORTS", "") == (value if name == "FASTDDS_BUILTIN_TRANSPORTS" else "")


IMAGE_BYTES = 640 * 480 * 4  # a 32FC1 depth image: fragmented over UDP

SUBSCRIBER = textwrap.dedent(
    """
    import os, rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import Image
    from arm_ros.common import use_large_socket_buffers
    use_large_socket_buffers()
    rclpy.init()
    node = rclpy.create_node("large_image_subscriber")
    got = []
    qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
    node.create_subscription(Image, "large_image", lambda m: got.append(len(m.data)), qos)
    while not got:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(os.environ["FASTDDS_BUILTIN_TRANSPORTS"], got[0], flush=True)
    """
)

PUBLISHER = textwrap.dedent(
    f"""
    import time, rclpy
    from sensor_msgs.msg import Image
    rclpy.init()
    node = rclpy.create_node("large_image_publisher")
    publisher = node.create_publisher(Image, "large_image", 10)
    image = Image(height=480, width=640, encoding="32FC1", step=2560, data=bytes({IMAGE_BYTES}))
    while True:
        publisher.publish(image)
        time.sleep(0.05)
    """
)


def test_a_node_with_large_buffers_receives_a_fragmented_image_from_a_default_publisher():
    use_private_domain()  # this process's domain (and localhost only), for both processes
    env = {k: v for k, v in os.environ.items() if k not in (*VARIABLES, "FASTDDS_BUILTIN_TRANSPORTS")}
    publisher = subprocess.Popen([sys.executable, "-c", PUBLISHER], env=env)
    try:
        done = subprocess.run([sys.executable, "-c", SUBSCRIBER], env=env, capture_output=True, text=True, timeout=60)
    finally:
        publisher.kill()
        publisher.wait()
    assert done.returncode == 0, done.stderr
    mode, received = done.stdout.split()
    assert mode == f"UDPv4?sockets_size={DDS_SOCKET_BUFFER_BYTES}"
    assert int(received) == IMAGE_BYTES
