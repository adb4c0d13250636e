import numpy as np

from arm_reconstruction.colour import GREY, vertex_colours


def test_seen_vertices_take_their_pixel_and_hidden_ones_the_objects_mean_colour():
    K = np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]])
    T_world_camera = np.eye(4)  # world = optical frame: z forward
    rgb = np.zeros((100, 100, 3), np.uint8)
    labels = np.zeros((100, 100), np.uint16)
    depth = np.zeros((100, 100), np.float32)
    labels[40:60, 40:60], depth[40:60, 40:60] = 3, 1.0
    rgb[40:60, 40:50] = (200, 0, 0)  # left half red, right half blue
    rgb[40:60, 50:60] = (0, 0, 200)
    vertices = np.array([
        [-0.05, 0.0, 1.0],  # seen on the red half
        [0.05, 0.0, 1.0],  # seen on the blue half
        [0.0, 0.0, 1.15],  # behind the seen surface: hidden
        [1.0, 0.0, 1.0],  # outside the image
    ])  # fmt: skip
    colours = vertex_colours(vertices, rgb, depth, labels, 3, K, T_world_camera)
    assert colours.dtype == np.uint8 and colours.shape == (4, 3)
    assert colours[0].tolist() == [200, 0, 0] and colours[1].tolist() == [0, 0, 200]
    assert colours[2].tolist() == colours[3].tolist() == [100, 0, 100]  # the mean of the object's pixels
    assert vertex_colours(vertices, rgb, depth, labels, 9, K, T_world_camera)[0].tolist() == GREY.tolist()
