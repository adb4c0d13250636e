"""QueueAwareMultiThreadedExecutor: every message delivered, no resubmission storm behind a long callback."""

import threading
import time

import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from std_msgs.msg import Int32

from arm_ros.executors import QueueAwareMultiThreadedExecutor


class CountingExecutor(QueueAwareMultiThreadedExecutor):
    def __init__(self, num_threads):
        super().__init__(num_threads)
        self.submissions = 0

    def _run(self, handler) -> None:
        self.submissions += 1
        super()._run(handler)


def test_messages_arrive_without_resubmitting_queued_callbacks_while_a_long_callback_holds_the_gil():
    rclpy.init()
    try:
        node = rclpy.create_node("executor_test")
        received, long_done = [], threading.Event()

        def hold_the_gil() -> None:  # like an MPPI plan: Python work on a pool thread for a while
            end = time.perf_counter() + 1.5
            while time.perf_counter() < end:
                sum(range(200))
            long_done.set()

        node.create_subscription(
            Int32, "ticks", lambda msg: received.append(msg.data), 100, callback_group=MutuallyExclusiveCallbackGroup()
        )
        long_timer = node.create_timer(0.01, lambda: (long_timer.cancel(), hold_the_gil()), ReentrantCallbackGroup())
        executor = CountingExecutor(num_threads=3)
        executor.add_node(node)
        spinner = threading.Thread(target=executor.spin, daemon=True)
        spinner.start()

        publisher_node = rclpy.create_node("executor_test_publisher")
        publisher = publisher_node.create_publisher(Int32, "ticks", 100)
        deadline = time.monotonic() + 5.0
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        for i in range(100):  # 50 Hz for 2 s, overlapping the long callback
            publisher.publish(Int32(data=i))
            time.sleep(0.02)
        deadline = time.monotonic() + 5.0
        while len(received) < 100 and time.monotonic() < deadline:
            time.sleep(0.01)

        assert long_done.is_set()
        assert received == list(range(100))
        # one submission per message and per timer call, a few to spare; rclpy's own executor resubmits
        # each queued subscription Task on every turn of its loop (tens per message behind such a callback)
        assert executor.submissions <= 130, executor.submissions
        executor.shutdown()
        publisher_node.destroy_node()
        node.destroy_node()
    finally:
        rclpy.try_shutdown()
