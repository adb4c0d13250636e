"""Robot self filter: the pixels showing the robot's own arm, rendered from its joint positions.

As MoveIt's depth self filter does, the arm's link geometry (the capsules and boxes arm_sim.robot
builds, each covered by capsules here) is posed by forward kinematics and rasterised at the camera,
padded by a margin. A pixel is masked where it lies inside a padded link's silhouette and its
measured depth is at or behind that link's near side (or missing): an object in front of the arm
stays visible.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from arm_core.camera import pixel_coordinates
from arm_sim.robot import FLANGE_D_M, JOINT_NAMES, PANDA_DH, dh_link_transform

# Covering capsules (start, end in the link frame, radius m) of the geoms arm_sim.robot.add_panda
# attaches to the base, the hand (box 0.04 x 0.2 x 0.05 m) and the two fingers at any opening.
BASE_CAPSULE = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.12), 0.07)
HAND_YAW_RAD = -np.pi / 4
HAND_CAPSULES = (
    ((0.0, -0.08, 0.03), (0.0, 0.08, 0.03), 0.033),
    ((0.0, -0.05, 0.085), (0.0, 0.05, 0.085), 0.03),
)


@dataclass(frozen=True)
class SelfFilterParams:
    padding_m: float = 0.03  # added to every link's radius
    depth_margin_m: float = 0.05  # a pixel this far in front of a link's near side is still the link
    min_depth_m: float = 0.02  # sphere centres nearer than this to the camera plane are skipped


def link_capsules(q, T_world_base: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """World-frame capsules (start (3,), end (3,), radius m) covering the arm at joint positions q (7,)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1)
    if q.shape != (len(PANDA_DH),) or not np.all(np.isfinite(q)):
        raise ValueError(f"need {len(PANDA_DH)} finite joint positions, got {q.shape}")

    def world(T, start, end, radius):
        return T[:3, :3] @ np.asarray(start) + T[:3, 3], T[:3, :3] @ np.asarray(end) + T[:3, 3], radius

    T = np.asarray(T_world_base, dtype=np.float64)
    capsules = [world(T, *BASE_CAPSULE)]
    for i, ((a, d, alpha), qi) in enumerate(zip(PANDA_DH, q, strict=True)):
        T = T @ dh_link_transform(a, d, alpha, qi)
        if i + 1 < len(PANDA_DH):
            a_next, d_next, alpha_next = PANDA_DH[i + 1]
            child = dh_link_transform(a_next, d_next, alpha_next, 0.0)[:3, 3]
        else:
            child = np.array([0.0, 0.0, FLANGE_D_M])
        capsules.append(world(T, (0.0, 0.0, 0.0), child, 0.055 if i < 4 else 0.045))
    T_hand = T @ dh_link_transform(0.0, FLANGE_D_M, 0.0, HAND_YAW_RAD)
    capsules += [world(T_hand, *capsule) for capsule in HAND_CAPSULES]
    return capsules


def capsule_spheres(capsules, padding_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(centres (N, 3), radii (N,)): spheres along each capsule's axis, at most half a radius apart,
    grown by padding_m (their union covers the padded capsules)."""
    centres, radii = [], []
    for start, end, radius in capsules:
        n = int(np.ceil(np.linalg.norm(end - start) / (0.5 * radius))) + 1
        t = np.linspace(0.0, 1.0, n)[:, None]
        centres.append(start + t * (end - start))
        radii.append(np.full(n, radius + padding_m))
    return np.concatenate(centres), np.concatenate(radii)


def self_mask(
    q,
    T_world_base: np.ndarray,
    K: np.ndarray,
    T_world_camera: np.ndarray,
    shape: tuple[int, int],
    depth_m: np.ndarray | None = None,
    params: SelfFilterParams = SelfFilterParams(),
) -> np.ndarray:
    """HxW bool: the pixels of a camera (K, T_world_camera, image shape) that show the arm at joint
    positions q, padded by params.padding_m. With depth_m (HxW metres, 0 = no return), pixels
    measured clearly in front of the arm are left out."""
    centres, radii = capsule_spheres(link_capsules(q, T_world_base), params.padding_m)
    T_camera_world = np.linalg.inv(np.asarray(T_world_camera, dtype=np.float64))
    c = centres @ T_camera_world[:3, :3].T + T_camera_world[:3, 3]
    z = c[:, 2]
    ahead = z - radii > params.min_depth_m
    h, w = shape
    near = np.full((h, w), np.inf, dtype=np.float32)
    focal = max(K[0, 0], K[1, 1])
    us, vs = pixel_coordinates(c[ahead], K)
    for u, v, zc, r in zip(us, vs, z[ahead], radii[ahead], strict=True):  # one disc per sphere (about 100)
        rad = focal * r / np.sqrt(max(zc * zc - r * r, 1e-9))
        x0, x1 = int(max(np.floor(u - rad), 0)), int(min(np.ceil(u + rad) + 1, w))
        y0, y1 = int(max(np.floor(v - rad), 0)), int(min(np.ceil(v + rad) + 1, h))
        if x0 >= x1 or y0 >= y1:
            continue
        disc = np.zeros((y1 - y0, x1 - x0), dtype=np.uint8)
        cv2.circle(disc, (int(round(u)) - x0, int(round(v)) - y0), int(np.ceil(rad)), 1, -1)
        roi = near[y0:y1, x0:x1]
        np.minimum(roi, np.where(disc > 0, np.float32(zc - r), np.inf), out=roi)
    mask = np.isfinite(near)
    if depth_m is not None:
        depth = np.asarray(depth_m, dtype=np.float32)
        mask &= (depth <= 0) | ~np.isfinite(depth) | (depth >= near - params.depth_margin_m)
    return mask


def base_pose(xyz_m, yaw_rad: float = 0.0) -> np.ndarray:
    """4x4 world pose of the robot base at xyz_m turned by yaw_rad about +z."""
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    T[:3, 3] = np.asarray(xyz_m, dtype=np.float64).reshape(3)
    return T


def arm_positions(names, positions) -> np.ndarray:
    """The arm's 7 joint positions (arm_sim.robot.JOINT_NAMES order) from a JointState's names and
    positions. Raises ValueError for a state without them or with non-finite values."""
    names, positions = list(names), np.asarray(positions, dtype=np.float64).reshape(-1)
    if len(names) != len(positions):
        raise ValueError(f"joint state has {len(names)} names but {len(positions)} positions")
    index = {name: i for i, name in enumerate(names)}
    missing = [name for name in JOINT_NAMES if name not in index]
    if missing:
        raise ValueError(f"joint state lacks {missing}")
    q = positions[[index[name] for name in JOINT_NAMES]]
    if not np.all(np.isfinite(q)):
        raise ValueError("joint state holds non-finite positions")
    return q
