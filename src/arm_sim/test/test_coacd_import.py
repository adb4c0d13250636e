"""CoACD loaded through import_coacd cannot crash the ROS middleware loaded after it."""

import subprocess
import sys


def _exit_code(code: str) -> int:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120).returncode


def test_rclpy_imported_after_coacd_loaded_through_import_coacd_works():
    code = (
        "from arm_sim.coacd_import import import_coacd\n"
        "import_coacd()\n"
        "import rclpy\n"
        "rclpy.init()\n"
        "rclpy.create_node('after_coacd').destroy_node()\n"
        "rclpy.shutdown()\n"
    )
    assert _exit_code(code) == 0


def test_the_object_library_does_not_load_coacd_until_it_decomposes_a_mesh():
    assert _exit_code("import sys, arm_sim.objects\nassert 'coacd' not in sys.modules") == 0
