"""Pipeline objects <-> ROS messages (message classes only, no rclpy: testable without a ROS graph)."""

import colorsys
from dataclasses import dataclass

import numpy as np
import trimesh
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from arm_interfaces.msg import GridMetadata, ReconstructedObjectArray, SegmentedFrame
from arm_interfaces.msg import ReconstructedObject as ReconstructedObjectMsg
from arm_ros.conversions import (
    ConversionError,
    K_from_camera_info,
    camera_info_from_K,
    depth_to_metres,
    image_to_numpy,
    matrix_to_pose,
    msg_to_mesh,
    numpy_to_image,
    object_msg,
    pose_to_matrix,
)

from .grid import GridFrame
from .pipeline import ReconstructedObject

MARKER_NAMESPACE = "arm_meshes"


@dataclass
class FrameData:
    """A SegmentedFrame as arrays: rgb uint8 HxWx3 (None when absent), depth_m float32 HxW (0 = no
    return), K 3x3, T_world_camera 4x4, labels uint16 HxW."""

    rgb: np.ndarray | None
    depth_m: np.ndarray
    K: np.ndarray
    T_world_camera: np.ndarray
    labels: np.ndarray
    instance_ids: list[int]
    world_frame_id: str


def frame_from_msg(msg: SegmentedFrame) -> FrameData:
    """SegmentedFrame -> FrameData. Raises ConversionError on any malformed field."""
    depth_m = depth_to_metres(msg.depth)
    if msg.labels.encoding not in ("16UC1", "mono16"):
        raise ConversionError(f"labels encoding must be 16UC1, got '{msg.labels.encoding}'")
    labels = image_to_numpy(msg.labels)
    if labels.shape != depth_m.shape:
        raise ConversionError(f"labels {labels.shape} and depth {depth_m.shape} differ in size")
    rgb = None
    if msg.rgb.height and msg.rgb.width:
        rgb = image_to_numpy(msg.rgb)
        if rgb.shape[:2] != depth_m.shape:
            raise ConversionError(f"rgb {rgb.shape[:2]} and depth {depth_m.shape} differ in size")
    K = K_from_camera_info(msg.camera_info)
    info_size = (int(msg.camera_info.height), int(msg.camera_info.width))
    if info_size != (0, 0) and info_size != depth_m.shape:
        raise ConversionError(f"camera_info size {info_size} differs from depth {depth_m.shape}")
    T_world_camera = pose_to_matrix(msg.camera_pose)
    return FrameData(rgb, depth_m, K, T_world_camera, labels, [int(i) for i in msg.instance_ids], msg.world_frame_id)


def frame_to_msg(rgb, depth_m, K, T_world_camera, labels, header=None, world_frame_id: str = "world") -> SegmentedFrame:
    """Arrays -> SegmentedFrame (what arm_segmentation publishes; used by tools and tests)."""
    msg = SegmentedFrame()
    if header is not None:
        msg.header = header
    depth_m = np.asarray(depth_m, dtype=np.float32)
    if rgb is not None:
        msg.rgb = numpy_to_image(np.asarray(rgb, dtype=np.uint8), "rgb8", msg.header)
    msg.depth = numpy_to_image(depth_m, "32FC1", msg.header)
    msg.camera_info = camera_info_from_K(K, depth_m.shape[1], depth_m.shape[0], msg.header)
    msg.camera_pose = matrix_to_pose(T_world_camera)
    msg.world_frame_id = world_frame_id
    labels = np.asarray(labels, dtype=np.uint16)
    msg.labels = numpy_to_image(labels, "16UC1", msg.header)
    msg.instance_ids = [int(i) for i in np.unique(labels) if i > 0]
    return msg


def grid_to_msg(frame: GridFrame | None) -> GridMetadata:
    msg = GridMetadata()
    if frame is not None:
        msg.resolution = int(frame.resolution)
        msg.voxel_size_m = float(frame.voxel_size_m)
        msg.origin = Point(
            x=float(frame.origin_world[0]), y=float(frame.origin_world[1]), z=float(frame.origin_world[2])
        )
        msg.table_height_m = float(frame.table_height_m)
    return msg


def grid_from_msg(msg: GridMetadata) -> GridFrame | None:
    if msg.resolution == 0:
        return None
    origin = np.array([msg.origin.x, msg.origin.y, msg.origin.z])
    return GridFrame(origin, float(msg.voxel_size_m), int(msg.resolution), float(msg.table_height_m), "message")


def object_to_msg(obj: ReconstructedObject) -> ReconstructedObjectMsg:
    return object_msg(
        obj.id, obj.T_world_object, obj.mesh, obj.convex_parts, obj.visible_fraction, obj.method, grid_to_msg(obj.grid)
    )


def object_from_msg(msg: ReconstructedObjectMsg) -> ReconstructedObject:
    """ReconstructedObject message -> pipeline object (object frame meshes). Raises ConversionError."""
    vertices, faces = msg_to_mesh(msg.mesh)
    parts = [trimesh.Trimesh(*msg_to_mesh(p), process=False) for p in msg.convex_parts]
    return ReconstructedObject(
        int(msg.id),
        pose_to_matrix(msg.pose),
        trimesh.Trimesh(vertices, faces, process=False),
        parts,
        float(msg.visible_fraction),
        grid_from_msg(msg.grid),
        msg.method,
    )


def main_table_height(objects: list[ReconstructedObject], default_m: float = 0.0) -> float:
    """Median table height under the reconstructed objects (default_m when there are none)."""
    heights = [o.grid.table_height_m for o in objects if o.grid is not None and o.ok]
    return float(np.median(heights)) if heights else float(default_m)


def objects_to_msg(objects: list[ReconstructedObject], header, table_height_m: float) -> ReconstructedObjectArray:
    """The successfully reconstructed objects (ascending id) -> ReconstructedObjectArray."""
    msg = ReconstructedObjectArray(table_height_m=float(table_height_m))
    msg.header = header
    msg.objects = [object_to_msg(o) for o in sorted(objects, key=lambda o: o.id) if o.ok]
    return msg


def object_colour(object_id: int, alpha: float = 0.8) -> ColorRGBA:
    """A distinct, stable colour per object id (golden-ratio hue steps)."""
    r, g, b = colorsys.hsv_to_rgb((object_id * 0.618033988749895) % 1.0, 0.75, 0.95)
    return ColorRGBA(r=float(r), g=float(g), b=float(b), a=float(alpha))


def markers_msg(objects: list[ReconstructedObject], header, alpha: float = 0.8) -> MarkerArray:
    """A DELETEALL marker followed by one TRIANGLE_LIST marker per reconstructed object (id = object id)."""
    clear = Marker(action=Marker.DELETEALL, ns=MARKER_NAMESPACE)
    clear.header = header
    markers = [clear]
    for obj in sorted(objects, key=lambda o: o.id):
        if not obj.ok:
            continue
        marker = Marker(ns=MARKER_NAMESPACE, id=int(obj.id), type=Marker.TRIANGLE_LIST, action=Marker.ADD)
        marker.header = header
        marker.pose = matrix_to_pose(obj.T_world_object)
        marker.scale.x = marker.scale.y = marker.scale.z = 1.0
        marker.color = object_colour(obj.id, alpha)
        corners = np.asarray(obj.mesh.vertices)[np.asarray(obj.mesh.faces).reshape(-1)]
        marker.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in corners]
        markers.append(marker)
    return MarkerArray(markers=markers)
