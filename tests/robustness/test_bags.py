"""rosbag2 bags: round trips in both storages, and corrupt, truncated or missing bags handled with a
clear error by the core, by replay (exit code 2, no traceback) and by record."""

import numpy as np
import pytest
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Image

from arm_bags.bags import (
    BagError,
    BagReader,
    BagWriter,
    FrameGroups,
    LoopStamps,
    QosSpec,
    deserialize,
    header_stamp_ns,
    msgtype_name,
    read_bag,
    serialize,
    shift_stamps,
    write_bag,
)
from arm_benchmarks.robustness.bags import broken_bags as broken_bag_files
from arm_benchmarks.robustness.logs import tracebacks
from arm_benchmarks.robustness.messages import header_at
from arm_benchmarks.robustness.probe import Probe
from arm_interfaces.msg import ReconstructedObjectArray, SegmentedFrame
from arm_ros.conversions.images import numpy_to_image
from arm_ros.conversions.meshes import reconstructed_object_msg

from ros_helpers import start_node


def image(stamp_s, value=7, shape=(48, 64, 3)):
    return numpy_to_image(np.full(shape, value, np.uint8), "rgb8", header_at(stamp_s, "camera"))


def project_messages():
    frame = SegmentedFrame(header=header_at(1.0, "camera"), rgb=image(1.0), world_frame_id="world", instance_ids=[1, 2])
    box = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) * 0.05, np.array([[0, 1, 2], [0, 1, 3]]))
    meshes = ReconstructedObjectArray(header=header_at(1.0, "world"), table_height_m=0.01)
    meshes.objects = [reconstructed_object_msg(3, box, [box], 0.5, "arm")]
    return [
        ("/camera/color/image_raw", 10, image(1.0)),
        ("/arm/segmented_frame", 20, frame),
        ("/arm/meshes", 30, meshes),
        ("/camera/color/image_raw", 40, image(2.0, 9)),
    ]


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_round_trip_restores_equal_messages(tmp_path, storage):
    messages = project_messages()
    counts = write_bag(tmp_path / "bag", messages, storage)
    assert counts == {"/camera/color/image_raw": 2, "/arm/segmented_frame": 1, "/arm/meshes": 1}
    assert (tmp_path / "bag" / "metadata.yaml").exists()
    back = read_bag(tmp_path / "bag")
    assert [(t, ts) for t, ts, _ in back] == [(t, ts) for t, ts, _ in messages]
    for (_, _, original), (_, _, restored) in zip(messages, back, strict=True):
        # field by field, against what the wire carries (float32 fields; CDR padding is not deterministic)
        assert restored == deserialize(serialize(original), msgtype_name(original))
    with BagReader(tmp_path / "bag") as reader:
        assert reader.topics["/arm/meshes"] == "arm_interfaces/msg/ReconstructedObjectArray"
        assert reader.start_ns == 10 and reader.duration_ns == 30 and reader.message_count == 4


def test_offered_qos_is_stored(tmp_path):
    with BagWriter(tmp_path / "bag") as writer:
        writer.add_topic(
            "/arm/meshes",
            "arm_interfaces/msg/ReconstructedObjectArray",
            QosSpec(reliable=True, transient_local=True, depth=1),
        )
        writer.write_message("/arm/meshes", 5, ReconstructedObjectArray())
    assert BagReader(tmp_path / "bag").qos["/arm/meshes"] == QosSpec(reliable=True, transient_local=True, depth=1)


def test_unknown_type_and_existing_output_are_refused(tmp_path):
    with BagWriter(tmp_path / "bag") as writer, pytest.raises(BagError, match="no message definition"):
        writer.add_topic("/x", "nonexistent_msgs/msg/Thing")
    with pytest.raises(BagError, match="cannot create"):
        BagWriter(tmp_path / "bag")


def broken_bags(tmp_path) -> dict:
    return broken_bag_files(tmp_path, project_messages())


def test_broken_bags_raise_a_clear_bag_error(tmp_path):
    for name, path in broken_bags(tmp_path).items():
        with pytest.raises(BagError) as error:
            with BagReader(path) as reader:
                list(reader.messages())
        assert str(path.name) in str(error.value) or "does not exist" in str(error.value), name


def test_a_finished_storage_file_without_metadata_is_still_readable(tmp_path):
    write_bag(tmp_path / "bag", project_messages(), "mcap")
    (tmp_path / "bag" / "metadata.yaml").unlink()
    assert len(read_bag(tmp_path / "bag")) == 4


def test_corrupt_payload_raises_on_decode_only(tmp_path):
    with BagWriter(tmp_path / "bag") as writer:
        writer.write("/camera/color/image_raw", 1, b"\x00\x01\x00\x00" + b"\xff" * 16, "sensor_msgs/msg/Image")
    with BagReader(tmp_path / "bag") as reader:
        message = next(reader.messages())
        with pytest.raises(BagError, match="corrupt sensor_msgs/msg/Image"):
            message.decode()


def test_loop_offsets_keep_stamps_increasing():
    stamps = LoopStamps()
    for k in range(3):  # a 2 Hz camera recorded for 1 s: stamps 0.5, 1.0, 1.5 s
        stamps.observe("/camera/color/image_raw", int((k + 1) * 0.5e9), int((k + 1) * 0.5e9), 0)
    assert stamps.offset_ns(0) == 0 and stamps.offset_ns(1) == int(1.5e9) and stamps.offset_ns(2) == int(3.0e9)
    msg = image(1.5)
    shift_stamps(msg, stamps.offset_ns(1))
    assert header_stamp_ns(msg) == int(3.0e9)


def test_frame_groups_release_complete_frames_and_drop_stale_partial_ones():
    groups = FrameGroups({"rgb", "depth"})
    assert groups.add("rgb", 1, "a", 10) == []
    assert groups.add("rgb", 2, "b", 11) == []
    released = groups.add("depth", 2, "c", 12)
    assert [s for s, _ in released] == [2] and [t for t, _, _ in released[0][1]] == ["rgb", "depth"]
    assert groups.dropped == 1 and groups.pending == {}


def replay(tmp_path, *args, **params):
    process = start_node("replay", tmp_path, args=args, params={"wait_subscribers_s": 0.0, "linger_s": 0.2, **params})
    code = process.wait(60.0)
    if code is None:
        process.stop()
    return code, process.log()


def test_replay_refuses_broken_bags_with_exit_code_2(tmp_path):
    for name, path in broken_bags(tmp_path).items():
        code, log = replay(tmp_path, str(path))
        assert code == 2 and "invalid configuration" in log and not tracebacks(log), (name, log[-800:])
    code, log = replay(tmp_path)
    assert code == 2 and "must name a bag" in log
    write_bag(tmp_path / "ok", project_messages(), "mcap")
    code, log = replay(tmp_path, str(tmp_path / "ok"), topics=["/not/in/bag"])
    assert code == 2 and "not in the bag" in log


def test_replay_skips_corrupt_messages_and_publishes_the_rest(tmp_path):
    with BagWriter(tmp_path / "bag") as writer:
        writer.write_message("/camera/color/image_raw", 1_000_000, image(1.0))
        writer.write("/camera/color/image_raw", 2_000_000, b"\x00\x01\x00\x00" + b"\xff" * 16)
        writer.write_message("/camera/color/image_raw", 3_000_000, image(3.0))
    probe = Probe()
    try:
        received = probe.record(Image, "/camera/color/image_raw", 10)
        code, log = replay(tmp_path, str(tmp_path / "bag"), wait_subscribers_s=10.0, linger_s=1.0)
        probe.wait_until(lambda: len(received) == 2, 5.0)
    finally:
        probe.close()
    assert code == 0 and not tracebacks(log), log[-800:]
    assert "1 corrupt message(s) skipped" in log and "[corrupt_message, seen 1x]" in log
    assert [round(m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, 3) for m in received] == [1.0, 3.0]


def test_record_refuses_an_existing_output_with_exit_code_2(tmp_path):
    (tmp_path / "exists").mkdir()
    process = start_node("record", tmp_path, args=(str(tmp_path / "exists"),))
    code = process.wait(60.0)
    if code is None:
        process.stop()
    assert code == 2 and "exists already" in process.log() and not tracebacks(process.log())


def test_replay_keeps_the_bag_timing_publishes_clock_and_loops_with_increasing_stamps(tmp_path):
    period_ns = 100_000_000  # a 10 Hz camera
    write_bag(
        tmp_path / "bag", [("/camera/color/image_raw", (k + 1) * period_ns, image((k + 1) * 0.1)) for k in range(5)]
    )
    probe = Probe()
    try:
        received = probe.record(Image, "/camera/color/image_raw", 20)
        clock = probe.record(Clock, "/clock", 100)
        code, log = replay(
            tmp_path, str(tmp_path / "bag"), loop=True, max_loops=2, wait_subscribers_s=10.0, linger_s=0.5
        )
        probe.wait_until(lambda: len(received) == 10, 5.0)
        with probe.lock:
            stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in received]
            arrivals = list(received.times)
            clock_s = [c.clock.sec + 1e-9 * c.clock.nanosec for c in clock]
    finally:
        probe.close()
    assert code == 0 and not tracebacks(log), log[-800:]
    assert len(stamps) == 10 and np.all(np.diff(stamps) > 0), stamps  # the second pass is shifted by 0.5 s
    assert np.allclose(stamps, 0.1 * np.arange(1, 11), atol=1e-6)
    assert abs(np.median(np.diff(arrivals)) - 0.1) < 0.03, np.diff(arrivals)
    assert clock_s and np.all(np.diff(clock_s) >= 0) and 0.1 <= clock_s[0] and clock_s[-1] <= 1.0 + 1e-6
