"""Analytic ray-cast RGB-D frames of boxes on a table, for tests that need exact ground truth."""

from dataclasses import dataclass

import numpy as np


@dataclass
class Box:
    centre: tuple[float, float, float]
    half_extent: tuple[float, float, float]
    yaw_rad: float = 0.0
    rgb: tuple[int, int, int] = (200, 60, 60)


def intrinsics(width=640, height=480, fovy_deg=45.0):
    f = 0.5 * height / np.tan(np.deg2rad(fovy_deg) / 2)
    return np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])


def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """T_world_camera of an optical frame (x right, y down, z forward) at eye looking at target."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def render(
    boxes,
    T_world_camera,
    K=None,
    width=640,
    height=480,
    table_levels=((0.0, 0.5),),
    table_rgb=(150, 130, 110),
    floor_z=-0.75,
    supports=(),
):
    """Ray-cast boxes standing on square table levels (height_m, half_extent_m) over a floor.

    `supports` are further boxes (shelves, steps) drawn in the table colour with label 0.
    Returns (rgb uint8, depth_m float32, labels uint16 with box i -> i + 1, K).
    """
    K = intrinsics(width, height) if K is None else K
    u, v = np.meshgrid(np.arange(width), np.arange(height))
    rays_c = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u, float)], -1)
    R, origin = T_world_camera[:3, :3], T_world_camera[:3, 3]
    rays_w = rays_c @ R.T
    best_t = np.full((height, width), np.inf)
    label = np.zeros((height, width), dtype=np.int64)
    normal = np.zeros((height, width, 3))
    colour = np.zeros((height, width, 3))
    surfaces = [(floor_z, 10.0, np.array([90, 90, 90]))]
    surfaces += [(h, e, np.array(table_rgb)) for h, e in table_levels]
    for h, extent, rgb in surfaces:
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (h - origin[2]) / rays_w[..., 2]
        hit = origin[:2] + t[..., None] * rays_w[..., :2]
        ok = (t > 0) & (np.abs(hit).max(-1) <= extent) & (t < best_t)
        best_t[ok], label[ok], normal[ok], colour[ok] = t[ok], 0, (0, 0, 1), rgb
    all_boxes = [(i + 1, b, b.rgb) for i, b in enumerate(boxes)] + [(0, b, table_rgb) for b in supports]
    for label_id, box, box_rgb in all_boxes:
        c, s = np.cos(box.yaw_rad), np.sin(box.yaw_rad)
        R_wb = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        o_b = R_wb.T @ (origin - np.asarray(box.centre))
        d_b = rays_w @ R_wb
        ext = np.asarray(box.half_extent)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-ext - o_b) / d_b
            t2 = (ext - o_b) / d_b
        t_near = np.minimum(t1, t2)
        t_enter = t_near.max(-1)
        t_exit = np.maximum(t1, t2).min(-1)
        axis = t_near.argmax(-1)
        ok = (t_enter <= t_exit) & (t_enter > 0) & (t_enter < best_t)
        n_b = np.zeros((height, width, 3))
        np.put_along_axis(n_b, axis[..., None], -np.sign(np.take_along_axis(d_b, axis[..., None], -1)), -1)
        best_t[ok], label[ok], normal[ok], colour[ok] = t_enter[ok], label_id, (n_b @ R_wb.T)[ok], box_rgb
    light = np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0])
    shade = 0.45 + 0.55 * np.clip(normal @ light, 0, 1)
    rgb = np.clip(colour * shade[..., None], 0, 255).astype(np.uint8)
    depth = np.where(np.isfinite(best_t), best_t * rays_c[..., 2], 0).astype(np.float32)
    return rgb, depth, label.astype(np.uint16), K


def add_noise(depth, rng, sigma_at_1m=0.002, dropout=0.01):
    """Depth noise growing with depth squared, plus random missing pixels."""
    noisy = depth + rng.normal(0, 1, depth.shape).astype(np.float32) * sigma_at_1m * depth * depth
    noisy[rng.random(depth.shape) < dropout] = 0.0
    return noisy.astype(np.float32)
