"""run_node: a node process that crashes in native code leaves its threads' Python stacks in its log."""

import subprocess
import sys
import textwrap

CRASHING_NODE = textwrap.dedent(
    """
    import ctypes
    from rclpy.node import Node
    from arm_ros.common import run_node

    class Crashing(Node):
        def __init__(self):
            super().__init__("crashing_node")
            self.create_timer(0.05, self.crash_in_native_code)

        def crash_in_native_code(self):
            ctypes.string_at(0)  # reads address 0: SIGSEGV

    run_node(Crashing)
    """
)


def test_a_segfault_in_a_node_writes_the_python_stack_to_its_log():
    done = subprocess.run([sys.executable, "-c", CRASHING_NODE], capture_output=True, text=True, timeout=60)
    assert done.returncode != 0
    assert "Fatal Python error: Segmentation fault" in done.stderr
    assert "crash_in_native_code" in done.stderr, "the stack names the callback that crashed"
