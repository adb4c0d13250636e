"""Point, colour and triangle sequences built from arrays: the same messages, and the same bytes on
the wire, as the messages' own constructors give."""

import numpy as np
import pytest
from geometry_msgs.msg import Point
from rclpy.serialization import deserialize_message, serialize_message
from shape_msgs.msg import Mesh, MeshTriangle
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker

from arm_ros.conversions import sequences
from arm_ros.conversions.meshes import mesh_to_msg, msg_to_mesh


def _constructed_mesh(vertices, faces) -> Mesh:
    return Mesh(
        vertices=[Point(x=x, y=y, z=z) for x, y, z in vertices.tolist()],
        triangles=[MeshTriangle(vertex_indices=f) for f in faces.tolist()],
    )


@pytest.fixture
def mesh_arrays():
    rng = np.random.default_rng(0)
    return rng.normal(scale=0.1, size=(50, 3)), rng.integers(0, 50, size=(80, 3))


def test_direct_slots_are_used_for_jazzy_messages():
    assert all(sequences.DIRECT_SLOTS.values())


@pytest.mark.parametrize("direct", [True, False])
def test_meshes_serialize_as_the_constructors_do(mesh_arrays, monkeypatch, direct):
    if not direct:
        monkeypatch.setattr(sequences, "DIRECT_SLOTS", dict.fromkeys(sequences.DIRECT_SLOTS, False))
    vertices, faces = mesh_arrays
    built = mesh_to_msg(vertices, faces)
    assert built == _constructed_mesh(vertices, faces)
    wire = serialize_message(built)
    assert wire == serialize_message(_constructed_mesh(vertices, faces))
    got_vertices, got_faces = msg_to_mesh(deserialize_message(wire, Mesh))
    np.testing.assert_array_equal(got_vertices, vertices)
    np.testing.assert_array_equal(got_faces, faces)
    assert got_faces.dtype == np.int64


@pytest.mark.parametrize("direct", [True, False])
def test_marker_colours_serialize_as_the_constructors_do(monkeypatch, direct):
    if not direct:
        monkeypatch.setattr(sequences, "DIRECT_SLOTS", dict.fromkeys(sequences.DIRECT_SLOTS, False))
    rgb = np.random.default_rng(1).uniform(size=(30, 3))
    built = Marker(colors=sequences.colours_from_array(rgb, 0.8))
    constructed = Marker(colors=[ColorRGBA(r=r, g=g, b=b, a=0.8) for r, g, b in rgb.tolist()])
    assert serialize_message(built) == serialize_message(constructed)


def test_the_triangles_do_not_share_the_callers_array(mesh_arrays):
    _, faces = mesh_arrays
    faces = faces.astype(np.uint32)
    triangles = sequences.triangles_from_array(faces)
    faces[0] = 7
    assert list(triangles[0].vertex_indices) != [7, 7, 7]


def test_empty_sequences():
    assert sequences.points_from_array(np.zeros((0, 3))) == []
    assert sequences.triangles_from_array(np.zeros((0, 3), dtype=int)) == []
    assert sequences.array_from_points([]).shape == (0, 3)
    assert sequences.array_from_triangles([]).shape == (0, 3)
