"""Record a short sim run to a bag while segmentation + reconstruction run live, then replay the bag
through fresh segmentation + reconstruction nodes: the meshes of every frame both runs
reconstructed are the same."""

import pathlib
import shutil
import tempfile

import numpy as np
import pytest

from arm_bags.bags import BagReader, header_stamp_ns
from arm_benchmarks.robustness.logs import tracebacks
from arm_benchmarks.robustness.messages import stamp_of
from arm_benchmarks.robustness.probe import Probe
from arm_interfaces.msg import ReconstructedObjectArray
from arm_ros.common import latched_qos
from arm_ros.conversions.meshes import reconstructed_object_from_msg
from arm_ros.processes import NodeProcess

from ros_helpers import require_built, require_reconstruction_params

CAMERA = ["camera/color/image_raw", "camera/depth/image_raw", "camera/camera_info", "camera/pose"]
SIM = {"n_objects": 4, "camera_rate_hz": 0.25, "width": 320, "height": 240}  # live reconstruction keeps up


@pytest.fixture(scope="module")
def recon_params():
    require_built("sim", "segmentation", "reconstruction", "record", "replay")
    return require_reconstruction_params()


@pytest.fixture
def work_dir():
    """Bag and node logs, outside pytest's shared basetemp (other sessions prune it during long runs)."""
    path = pathlib.Path(tempfile.mkdtemp(prefix="arm_bag_replay_"))
    yield path
    shutil.rmtree(path, ignore_errors=True)


def pipeline(log_dir, recon_params):
    return [
        NodeProcess("segmentation", log_dir / "segmentation.log", params={"image_reliability": "reliable"}),
        NodeProcess("reconstruction", log_dir / "reconstruction.log", params=recon_params),
    ]


def meshes_by_stamp(store) -> dict[float, ReconstructedObjectArray]:
    return {round(stamp_of(m), 6): m for m in list(store)}


def test_replayed_bag_reproduces_the_live_meshes(work_dir, recon_params):
    probe = Probe()
    bag = work_dir / "demo_bag"
    try:
        live_store = probe.record(ReconstructedObjectArray, "arm/meshes", latched_qos(depth=10))
        live = [NodeProcess("sim", work_dir / "live" / "sim.log", params=SIM)]
        live += pipeline(work_dir / "live", recon_params)
        recorder = NodeProcess(
            "record",
            work_dir / "live" / "record.log",
            args=(str(bag),),
            params={"use_sim_time": True, "topics": CAMERA + ["joint_states"]},
        )
        try:
            live_ok = probe.wait_until(lambda: len(meshes_by_stamp(live_store)) >= 2, 240.0, poll_s=0.2)
        finally:
            recorder_code = recorder.stop()
            for process in live:
                process.stop()
        assert live_ok, "no live meshes"
        assert recorder_code == 0, recorder.log()[-2000:]
        live_meshes = meshes_by_stamp(live_store)

        with BagReader(bag) as reader:
            assert set(reader.topics) == {"/" + t for t in CAMERA} | {"/joint_states"}
            depth_times = {
                round(header_stamp_ns(m.decode()) * 1e-9, 6): m.timestamp_ns
                for m in reader.messages(["/camera/depth/image_raw"])
            }
            start_ns = reader.start_ns
        stamps = sorted(s for s in live_meshes if s in depth_times)
        assert stamps, f"live stamps {sorted(live_meshes)} are not in the bag"
        window = (min(depth_times[s] for s in stamps) - start_ns - 2e8, max(depth_times[s] for s in stamps) + 2e8)

        probe_replay = Probe("replay_probe")
        try:
            replay_store = probe_replay.record(ReconstructedObjectArray, "arm/meshes", latched_qos(depth=10))
            nodes = pipeline(work_dir / "replay", recon_params)
            # The mesh publisher keeps only its last message for late subscribers: match it before
            # the first frame, or a slow discovery hides that frame's meshes from this probe.
            matched = probe_replay.wait_until(lambda: replay_store.subscription.get_publisher_count() > 0, 120.0)
            assert matched, "the replay probe never matched the reconstruction node's publisher"
            replay = NodeProcess(
                "replay",
                work_dir / "replay" / "replay.log",
                args=(str(bag),),
                params={
                    "mode": "consumed",
                    "topics": CAMERA + ["joint_states"],  # the self filter needs the arm's joint states
                    "start_offset_s": max(0.0, window[0] * 1e-9),
                    "duration_s": (window[1] - start_ns) * 1e-9 - max(0.0, window[0] * 1e-9),
                    "wait_subscribers_s": 60.0,
                    "consumed_timeout_s": 180.0,
                },
            )
            try:
                code = replay.wait(400.0)
            finally:
                replay.stop()
                for process in nodes:
                    process.stop()
            replay_meshes = meshes_by_stamp(replay_store)
        finally:
            probe_replay.close()
    finally:
        probe.close()

    log = replay.log()
    assert code == 0 and not tracebacks(log), log[-2000:]
    assert "timed out 0" in log, log[-1000:]
    for stamp in stamps:
        assert stamp in replay_meshes, f"frame {stamp} was not reconstructed in the replay ({sorted(replay_meshes)})"
        a, b = live_meshes[stamp], replay_meshes[stamp]
        assert [o.id for o in a.objects] == [o.id for o in b.objects] and len(a.objects) > 0
        for obj_a, obj_b in zip(a.objects, b.objects, strict=True):
            Ta, (Va, Fa), parts_a = reconstructed_object_from_msg(obj_a)
            Tb, (Vb, Fb), parts_b = reconstructed_object_from_msg(obj_b)
            np.testing.assert_allclose(Ta, Tb, atol=1e-9)
            assert np.array_equal(Fa, Fb) and len(parts_a) == len(parts_b)
            np.testing.assert_allclose(Va, Vb, atol=1e-9)
