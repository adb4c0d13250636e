"""sensor_msgs/PointCloud2 of labelled points <-> numpy.

The cloud has the fields x, y, z (float32, metres, in the header's frame), rgb (float32 holding the
packed 0x00RRGGBB colour, as PCL and RViz's RGB8 colour transformer read it) and label (uint32,
the instance id), 20 bytes a point, unorganised (height 1), little-endian.
"""

import numpy as np
from sensor_msgs.msg import PointCloud2, PointField

from arm_ros.conversions import ConversionError

CLOUD_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4"), ("label", "<u4")])
FIELDS = [
    PointField(name="x", offset=0, datatype=PointField.FLOAT32, count=1),
    PointField(name="y", offset=4, datatype=PointField.FLOAT32, count=1),
    PointField(name="z", offset=8, datatype=PointField.FLOAT32, count=1),
    PointField(name="rgb", offset=12, datatype=PointField.FLOAT32, count=1),
    PointField(name="label", offset=16, datatype=PointField.UINT32, count=1),
]


def labelled_cloud_msg(points: np.ndarray, rgb: np.ndarray, labels: np.ndarray, header) -> PointCloud2:
    """PointCloud2 of N points (N, 3) metres, their colours (N, 3) uint8 and instance labels (N,)."""
    points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    rgb = np.asarray(rgb, dtype=np.uint32).reshape(-1, 3)
    cloud = np.empty(len(points), dtype=CLOUD_DTYPE)
    cloud["x"], cloud["y"], cloud["z"] = points.T
    cloud["rgb"] = (rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]
    cloud["label"] = np.asarray(labels, dtype=np.uint32).reshape(-1)
    return PointCloud2(
        header=header,
        height=1,
        width=len(cloud),
        fields=FIELDS,
        is_bigendian=False,
        point_step=CLOUD_DTYPE.itemsize,
        row_step=CLOUD_DTYPE.itemsize * len(cloud),
        data=cloud.tobytes(),
        is_dense=True,
    )


def labelled_cloud_to_numpy(msg: PointCloud2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (N, 3) float32, colours (N, 3) uint8, labels (N,) uint32) of a cloud written by
    labelled_cloud_msg. Raises ConversionError for another layout."""
    names = [(f.name, f.offset, f.datatype) for f in msg.fields]
    if names != [(f.name, f.offset, f.datatype) for f in FIELDS] or msg.point_step != CLOUD_DTYPE.itemsize:
        raise ConversionError(f"not a labelled cloud (x, y, z, rgb, label): fields {names}")
    n = int(msg.width) * int(msg.height)
    if len(msg.data) < n * CLOUD_DTYPE.itemsize:
        raise ConversionError(f"cloud data too short: {len(msg.data)} bytes for {n} points")
    cloud = np.frombuffer(bytes(msg.data), dtype=CLOUD_DTYPE, count=n)
    packed = cloud["rgb"]
    colours = np.stack([(packed >> 16) & 0xFF, (packed >> 8) & 0xFF, packed & 0xFF], axis=1).astype(np.uint8)
    return np.stack([cloud["x"], cloud["y"], cloud["z"]], axis=1), colours, cloud["label"].copy()
