"""Cluttered tabletop scenes (paper appendix "Cluttered Reconstruction Benchmark Details") and
manipulation task scenes (appendix "Cluttered Manipulation Benchmark")."""

from dataclasses import dataclass, field

import mujoco
import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from arm_core.camera import look_at
from arm_sim.appearance import DEFAULT_DOMAIN, DOMAINS, SceneAppearance, sample_appearance
from arm_sim.depth_noise import DepthNoise
from arm_sim.objects import ObjectModel, ObjectPool
from arm_sim.world import (
    FLOOR_DROP_M,
    OBJECT_DENSITY_KG_M3,
    ROBOT_BASE_XY,
    SLIDING_FRICTION,
    SimWorld,
    object_body_name,
)

DROP_REGION_X = (-0.2, 0.3)  # drop centres stay clear of the robot base at x = -0.55
DROP_REGION_Y = (-0.3, 0.3)
TASK_TARGET_XY = (0.0, 0.0)


@dataclass
class PlacedObject:
    model: ObjectModel
    scale: float
    T_world_object: np.ndarray
    rgba: tuple = (0.7, 0.7, 0.7, 1.0)
    density_kg_m3: float = OBJECT_DENSITY_KG_M3

    def convex_parts_local(self) -> list[tuple[np.ndarray, np.ndarray]]:
        parts = self.model.convex_parts or [self.model.mesh.convex_hull]
        return [(p.vertices * self.scale, p.faces) for p in parts]

    def world_mesh(self) -> trimesh.Trimesh:
        mesh = self.model.mesh.copy()
        mesh.apply_scale(self.scale)
        mesh.apply_transform(self.T_world_object)
        return mesh


@dataclass
class Scene:
    objects: list[PlacedObject] = field(default_factory=list)
    table_height_m: float = 0.0
    table_half_extent_m: tuple = (0.7, 0.5)
    table_rgba: tuple = (0.55, 0.45, 0.35, 1.0)
    appearance: SceneAppearance | None = None  # None: the plain domain
    friction: float = SLIDING_FRICTION  # object-table and object-object sliding friction coefficient
    robot_base_xy: tuple = ROBOT_BASE_XY  # world x, y of the robot base (it stands on the table), metres

    @property
    def table_centre(self) -> np.ndarray:
        return np.array([0.0, 0.0, self.table_height_m])

    def with_poses(self, poses: list[np.ndarray], keep: np.ndarray | None = None) -> "Scene":
        keep = np.ones(len(self.objects), bool) if keep is None else keep
        objects = [
            PlacedObject(o.model, o.scale, T, o.rgba, o.density_kg_m3)
            for o, T, k in zip(self.objects, poses, keep, strict=True)
            if k
        ]
        appearance = None if self.appearance is None else self.appearance.subset(keep)
        return Scene(
            objects, self.table_height_m, self.table_half_extent_m, self.table_rgba, appearance, self.friction,
            self.robot_base_xy,
        )  # fmt: skip

    def with_domain(self, domain: str, rng: np.random.Generator) -> "Scene":
        """This scene in a visual domain ("realistic": a look drawn from a child of rng, so the
        caller's own random stream, and with it the scene's geometry, stays as in the plain domain)."""
        if domain not in DOMAINS:
            raise ValueError(f"unknown visual domain {domain!r}; expected one of {DOMAINS}")
        appearance = None
        if domain == "realistic":
            floor_z = self.table_height_m - FLOOR_DROP_M
            appearance = sample_appearance(
                rng.spawn(1)[0], len(self.objects), self.table_height_m, self.table_half_extent_m, floor_z
            )
        table = (self.table_height_m, self.table_half_extent_m, self.table_rgba)
        return Scene(self.objects, *table, appearance, self.friction)


def random_rotation(rng: np.random.Generator, upright_probability: float) -> np.ndarray:
    """Upright with a random yaw with the given probability, else uniformly random."""
    if rng.uniform() < upright_probability:
        return Rotation.from_euler("z", rng.uniform(0, 2 * np.pi)).as_matrix()
    return Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix()


def _random_rgba(rng: np.random.Generator) -> tuple:
    return (*rng.uniform(0.05, 0.95, 3).tolist(), 1.0)


def _pose_resting(model: ObjectModel, scale: float, rotation: np.ndarray, xy, z_floor: float) -> np.ndarray:
    """Pose with the rotated object's lowest point at z_floor."""
    T = np.eye(4)
    T[:3, :3] = rotation
    lowest = float(np.min((model.mesh.vertices * scale) @ rotation.T, axis=0)[2])
    T[:3, 3] = (xy[0], xy[1], z_floor - lowest)
    return T


def settle_scene(scene: Scene, seconds: float = 2.5) -> Scene:
    """Let physics settle the scene; drop objects that left the table."""
    world = SimWorld(scene, robot_arm=False)
    world.settle(seconds)
    poses = world.object_poses()
    keep = np.array([T[2, 3] > scene.table_height_m - 0.05 for T in poses])
    world.close()
    return scene.with_poses(poses, keep)


def cluttered_scene(
    pool: ObjectPool,
    rng: np.random.Generator,
    n_objects: int | None = None,
    scale_range=(0.5, 2.0),
    upright_probability: float = 0.75,
    drop_std_m: float = 0.1,
    drop_height_m: float = 0.2,
    table_height_m: float = 0.0,
    settle_s: float = 2.5,
    domain: str = DEFAULT_DOMAIN,
) -> Scene:
    """Objects dropped around a random centre on the table and settled by physics.

    n_objects defaults to uniform(3, 20); objects are stacked in height at the start where their
    bounding spheres would overlap, so that no two start interpenetrating."""
    n = int(rng.integers(3, 21)) if n_objects is None else int(n_objects)
    centre = np.array([rng.uniform(*DROP_REGION_X), rng.uniform(*DROP_REGION_Y)])
    scene = Scene(table_height_m=table_height_m, table_rgba=_random_rgba(rng))
    spheres = []  # (x, y, z_centre, radius)
    for _ in range(n):
        model = pool.sample(rng)
        scale = float(rng.uniform(*scale_range))
        rotation = random_rotation(rng, upright_probability)
        xy = centre + rng.normal(scale=drop_std_m, size=2)
        radius = 0.5 * float(np.linalg.norm(model.mesh.extents)) * scale
        z_bottom = table_height_m + drop_height_m
        for x, y, zc, r in spheres:
            if np.hypot(xy[0] - x, xy[1] - y) < r + radius:
                z_bottom = max(z_bottom, zc + r + 0.005)
        T = _pose_resting(model, scale, rotation, xy, z_bottom)
        height = float(np.ptp((model.mesh.vertices * scale) @ rotation.T, axis=0)[2])
        spheres.append((xy[0], xy[1], z_bottom + 0.5 * height, max(radius, 0.5 * height)))
        scene.objects.append(PlacedObject(model, scale, T, _random_rgba(rng)))
    return settle_scene(scene, settle_s).with_domain(domain, rng)


def task_camera_pose(table_height_m: float = 0.0) -> np.ndarray:
    """The fixed robot-side view of the manipulation tasks: across the table, towards the robot."""
    return look_at((0.8, 0.0, table_height_m + 0.32), (0.0, 0.0, table_height_m + 0.05))


def _visible_fraction(scene: Scene, index: int, T_world_camera: np.ndarray) -> float:
    world = SimWorld(scene, robot_arm=False)
    frame = world.render(T_world_camera, noise=DepthNoise(enabled=False))
    world.close()
    return float(frame.visible_fraction[index])


def _slide_into_range(scene, candidate, disc, occupied, visible_range, camera, steps: int = 7):
    """Bisect the sideways (y) offset of an occluder that hides too much of the target (index 0)
    between where it stands and 0.5 m further out. Returns (scene, visible fraction, disc) with the
    fraction inside visible_range, or (None, nan, None)."""
    lo, hi = visible_range
    (x, y), radius = disc
    side = 1.0 if y >= TASK_TARGET_XY[1] else -1.0
    near, far = y, y + side * 0.5
    table = (scene.table_height_m, scene.table_half_extent_m, scene.table_rgba)
    trial = Scene(scene.objects + [candidate], *table)
    world = SimWorld(trial, robot_arm=False)
    y_adr = world.model.joint(f"{object_body_name(len(scene.objects))}_joint").qposadr[0] + 1
    try:
        for _ in range(steps):
            mid = 0.5 * (near + far)
            if any(np.hypot(x - c[0], mid - c[1]) <= r + radius + 0.005 for c, r in occupied):
                return None, float("nan"), None
            world.data.qpos[y_adr] = mid  # the free joint's qpos is the body's world position
            mujoco.mj_kinematics(world.model, world.data)
            frame = world.render(camera, noise=DepthNoise(enabled=False), with_visibility=False)
            v = float(world.visible_fractions(frame.labels, camera)[0])
            if lo <= v < hi:
                T = candidate.T_world_object.copy()
                T[1, 3] = mid
                moved = PlacedObject(candidate.model, candidate.scale, T, candidate.rgba)
                return Scene(trial.objects[:-1] + [moved], *table), v, ((x, mid), radius)
            near, far = (mid, far) if v < lo else (near, mid)
    finally:
        world.close()
    return None, float("nan"), None


def task_scene(
    target: ObjectModel,
    distractor_pool: ObjectPool,
    rng: np.random.Generator,
    visible_range=(0.0, 1.01),
    target_scale: float = 1.0,
    distractor_scale_range=(0.5, 2.0),
    extra_distractors=(1, 7),
    table_height_m: float = 0.0,
    max_tries: int = 40,
    domain: str = DEFAULT_DOMAIN,
) -> tuple[Scene, int, np.ndarray]:
    """A manipulation scene: the target upright at a fixed spot, distractors added directly in front
    of it (towards the camera, y ~ N(target y, 0.1 m)) until its visible fraction falls in
    visible_range (one that hides nothing is dropped, one that hides too much is slid sideways until it
    does not), then 1-7 more distractors (0.25 m std) that keep it in range.

    Returns (scene, target index, T_world_camera). Raises RuntimeError if the range is not reached."""
    camera = task_camera_pose(table_height_m)
    scene = Scene(table_height_m=table_height_m, table_rgba=_random_rgba(rng))
    T = _pose_resting(target, target_scale, random_rotation(rng, 1.0), TASK_TARGET_XY, table_height_m)
    scene.objects.append(PlacedObject(target, target_scale, T, _random_rgba(rng)))
    lo, hi = visible_range
    visible = _visible_fraction(scene, 0, camera)
    occupied = [(TASK_TARGET_XY, 0.5 * float(np.max(target.mesh.extents[:2])) * target_scale)]

    def try_add(x_mean, x_std, y_std):
        model = distractor_pool.sample(rng)
        scale = float(rng.uniform(*distractor_scale_range))
        radius = 0.5 * float(np.max(model.mesh.extents[:2])) * scale
        for _ in range(20):
            xy = (rng.normal(x_mean, x_std), rng.normal(TASK_TARGET_XY[1], y_std))
            if all(np.hypot(xy[0] - c[0], xy[1] - c[1]) > r + radius + 0.005 for c, r in occupied):
                pose = _pose_resting(model, scale, random_rotation(rng, 1.0), xy, table_height_m)
                return PlacedObject(model, scale, pose, _random_rgba(rng)), (xy, radius)
        return None, None

    tries = 0
    while not (lo <= visible < hi):
        tries += 1
        if tries > max_tries:
            raise RuntimeError(f"could not reach visible fraction in [{lo}, {hi}) (last {visible:.2f})")
        candidate, disc = try_add(TASK_TARGET_XY[0] + 0.13, 0.04, 0.1)
        if candidate is None:
            continue
        trial = Scene(scene.objects + [candidate], scene.table_height_m, scene.table_half_extent_m, scene.table_rgba)
        v = _visible_fraction(trial, 0, camera)
        if v < lo:  # it hides too much: slide it sideways, out of the line of sight, until in range
            trial, v, disc = _slide_into_range(scene, candidate, disc, occupied, (lo, hi), camera)
        if trial is not None and lo <= v < visible - 0.01:
            scene, visible = trial, v
            occupied.append(disc)
    for _ in range(int(rng.integers(extra_distractors[0], extra_distractors[1] + 1))):
        candidate, disc = try_add(TASK_TARGET_XY[0], 0.25, 0.25)
        if candidate is None:
            continue
        trial = Scene(scene.objects + [candidate], scene.table_height_m, scene.table_half_extent_m, scene.table_rgba)
        v = _visible_fraction(trial, 0, camera)
        if lo <= v < hi:
            scene, visible = trial, v
            occupied.append(disc)
    return settle_scene(scene, 1.0).with_domain(domain, rng), 0, camera
