"""Reconstructed objects <-> ROS messages: ReconstructedObject(Array) and RViz markers (message
classes only, no rclpy: testable without a ROS graph). Frames are decoded by arm_ros.conversions.frames."""

import colorsys

import numpy as np
import trimesh
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from arm_interfaces.msg import GridMetadata, ReconstructedObjectArray
from arm_interfaces.msg import ReconstructedObject as ReconstructedObjectMsg
from arm_ros.conversions.meshes import object_msg, reconstructed_object_from_msg
from arm_ros.conversions.poses import matrix_to_pose, matrix_to_transform_msg
from arm_ros.conversions.sequences import colours_from_array, points_from_array

from .grid import GridFrame
from .pipeline import ReconstructedObject

MARKER_NAMESPACE = "arm_meshes"


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
    T_world_object, (vertices, faces), parts = reconstructed_object_from_msg(msg)
    return ReconstructedObject(
        int(msg.id),
        T_world_object,
        trimesh.Trimesh(vertices, faces, process=False),
        [trimesh.Trimesh(v, f, process=False) for v, f in parts],
        float(msg.visible_fraction),
        grid_from_msg(msg.grid),
        msg.method,
    )


def main_table_height(objects: list[ReconstructedObject], default_m: float = 0.0) -> float:
    """Median table height under the reconstructed objects whose grid saw a support (default_m when
    none did). An object without a support in view (its grid starts at its own lowest point, table
    source 'object') says nothing of the table: a patch found on top of a box would lift the table
    to the box's top."""
    grids = [o.grid for o in objects if o.grid is not None and o.ok]
    heights = [g.table_height_m for g in grids if g.table_source != "object"]
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
    """A DELETEALL marker followed by one TRIANGLE_LIST marker per reconstructed object (id = object id),
    coloured per vertex from the camera image where the object has vertex colours, else by its id."""
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
        corner_index = np.asarray(obj.mesh.faces).reshape(-1)
        corners = np.asarray(obj.mesh.vertices, dtype=np.float64)[corner_index]
        marker.points = points_from_array(corners)
        if obj.vertex_colours is not None and len(obj.vertex_colours) == len(obj.mesh.vertices):
            rgb = obj.vertex_colours[corner_index].astype(np.float64) / 255.0  # the camera's colours
            marker.colors = colours_from_array(rgb, alpha)
        markers.append(marker)
    return MarkerArray(markers=markers)


def object_frame(object_id: int) -> str:
    return f"object_{int(object_id)}"


def object_transforms(objects: list[ReconstructedObject], header) -> list:
    """TransformStamped of each reconstructed object's frame object_<id> (its mesh's frame: the world's
    axes, origin at the mesh centroid) in the header's world frame."""
    return [
        matrix_to_transform_msg(o.T_world_object, header.frame_id, object_frame(o.id), header.stamp)
        for o in objects
        if o.ok
    ]
