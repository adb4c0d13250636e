"""The one MuJoCo world builder (sim and planner twin) and the simulated world around it."""

import mujoco
import numpy as np

from arm_core.camera import intrinsics, silhouette
from arm_core.frames import RgbdFrame
from arm_sim import robot
from arm_sim.appearance import SceneAppearance, apply_camera_response, sample_camera_response
from arm_sim.camera import OPTICAL_TO_MUJOCO
from arm_sim.depth_noise import DepthNoise, SensorArtefacts, apply_depth_noise, apply_sensor_artefacts

RENDER_CAMERA = "render_camera"
ROBOT_BASE_XY = (-0.55, 0.0)
# The position servos take a new target this often (s): trajectories are interpolated at this rate, as a
# joint trajectory controller updates its command (the planner's twin ramps its targets per 0.01 s step too).
SERVO_PERIOD_S = 0.01
OBJECT_DENSITY_KG_M3 = 600.0
# Sliding friction between objects and the table (and between objects); MuJoCo takes the larger of
# two geoms' coefficients. 0.9 is high for household objects on a table (0.3-0.6 is typical): at
# 0.9 most of the procedural push targets tip before they slide (bench_pushability).
SLIDING_FRICTION = 0.9
TORSIONAL_FRICTION_M, ROLLING_FRICTION_M = 0.01, 0.001
FLOOR_DROP_M = 0.75
# Objects that interpenetrate deeper than this as built (the convex parts of reconstructed objects that
# touch overlap) get no contact with each other: the solver would push them apart and topple them.
OVERLAP_EXCLUDE_M = 0.002


def object_body_name(i: int) -> str:
    return f"object_{i}"


def build_world(scene, robot_arm: bool = True, timestep_s: float = 0.002, name: str = "arm_world") -> mujoco.MjModel:
    """MuJoCo model of a Scene: table, floor, one free body per object (its convex parts as mesh
    geoms), the robot and a render camera. The planner's twin is built by this same function."""
    return world_spec(scene, robot_arm, timestep_s, name).compile()


def world_spec(scene, robot_arm: bool = True, timestep_s: float = 0.002, name: str = "arm_world") -> mujoco.MjSpec:
    """The uncompiled MjSpec that build_world compiles (spec.to_xml() gives its MJCF)."""
    spec = mujoco.MjSpec()
    spec.modelname = name
    spec.compiler.degree = False
    spec.option.timestep = timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 960
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]
    table_z = float(scene.table_height_m)
    hx, hy = scene.table_half_extent_m
    friction = contact_friction(scene.friction)
    world = spec.worldbody
    world.add_light(pos=[0.3, -0.4, table_z + 2.0], dir=[-0.1, 0.2, -1.0], diffuse=[0.6, 0.6, 0.6])
    world.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[3, 3, 0.1],
        pos=[0, 0, table_z - FLOOR_DROP_M],
        rgba=[0.45, 0.42, 0.4, 1],
    )
    world.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=[hx, hy, 0.025],
        pos=[0, 0, table_z - 0.025],
        rgba=list(scene.table_rgba),
        friction=friction,
    )
    world.add_camera(name=RENDER_CAMERA, pos=[1.0, 0.0, table_z + 1.0], fovy=45.0)
    appearance = scene.appearance
    if appearance is not None:
        _add_surroundings(spec, appearance, scene.table_half_extent_m)
    for i, placed in enumerate(scene.objects):
        _add_object(spec, i, placed, friction, None if appearance is None else appearance.objects[i])
    if robot_arm:
        base_x, base_y = getattr(scene, "robot_base_xy", ROBOT_BASE_XY)
        robot.add_panda(spec, [float(base_x), float(base_y), table_z])
    return spec


def contact_friction(sliding: float) -> list[float]:
    """MuJoCo friction of the table and object geoms for a sliding coefficient (> 0, finite)."""
    sliding = float(sliding)
    if not np.isfinite(sliding) or sliding <= 0.0:
        raise ValueError(f"sliding friction must be a positive number, got {sliding}")
    return [sliding, TORSIONAL_FRICTION_M, ROLLING_FRICTION_M]


def _add_texture(spec: mujoco.MjSpec, name: str, image: np.ndarray, cube: bool) -> None:
    kind = mujoco.mjtTexture.mjTEXTURE_CUBE if cube else mujoco.mjtTexture.mjTEXTURE_2D
    texture = spec.add_texture(name=name, type=kind, width=image.shape[1], height=image.shape[0], nchannel=3)
    texture.data = np.ascontiguousarray(image, dtype=np.uint8).tobytes()


def _add_material(spec: mujoco.MjSpec, name: str, texture: str, repeat=(1.0, 1.0), uniform=False, shiny=False):
    material = spec.add_material(name=name, texrepeat=list(repeat), texuniform=uniform)
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = texture
    material.specular, material.shininess = (0.9, 0.9) if shiny else (0.15, 0.2)
    return material


def _add_surroundings(spec: mujoco.MjSpec, appearance: SceneAppearance, table_half_extent_m) -> None:
    """Textures of table and floor, table legs, furniture and lights of the realistic domain; none of
    it collides with anything."""
    spec.visual.headlight.ambient = list(appearance.ambient)
    spec.visual.headlight.diffuse = [0.25, 0.25, 0.25]
    spec.visual.quality.shadowsize = 1024
    for name, image in appearance.surfaces.items():
        _add_texture(spec, f"{name}_texture", image, cube=False)
    _add_material(spec, "table_material", "table_texture", appearance.table_texture_repeat, uniform=False)
    _add_material(spec, "floor_material", "floor_texture", (4.0, 4.0), uniform=True)
    _add_material(spec, "furniture_material", "furniture_texture", (1.0, 1.0), uniform=True)
    _add_material(spec, "wall_material", "wall_texture", (1.0, 1.0), uniform=True)
    for name in ("table", "floor"):
        spec.geom(name).material = f"{name}_material"
        spec.geom(name).rgba = [1.0, 1.0, 1.0, 1.0]
    for box in appearance.boxes:
        spec.worldbody.add_geom(
            name=box.name,
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(box.half_size_m),
            pos=list(box.centre_m),
            rgba=[*box.rgb, 1.0],
            material=f"{box.texture}_material" if box.texture else "",
            contype=0,
            conaffinity=0,
        )
    for light in appearance.lights:
        spec.worldbody.add_light(
            pos=list(light.pos_m),
            dir=list(light.direction),
            diffuse=list(light.diffuse),
            specular=list(light.specular),
            castshadow=light.cast_shadow and appearance.shadows,
        )


def _add_object(spec: mujoco.MjSpec, i: int, placed, friction: list[float], look=None) -> None:
    T = np.asarray(placed.T_world_object, dtype=np.float64)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, T[:3, :3].reshape(9))
    body = spec.worldbody.add_body(name=object_body_name(i), pos=T[:3, 3].tolist(), quat=quat.tolist())
    body.add_freejoint(name=f"{object_body_name(i)}_joint")
    material = ""
    if look is not None:
        material = f"{object_body_name(i)}_material"
        _add_texture(spec, f"{object_body_name(i)}_texture", look.texture, cube=True)
        _add_material(spec, material, f"{object_body_name(i)}_texture", shiny=look.shiny)
    for j, (vertices, faces) in enumerate(placed.convex_parts_local()):
        mesh_name = f"{object_body_name(i)}_mesh_{j}"
        spec.add_mesh(
            name=mesh_name,
            uservert=np.asarray(vertices, np.float64).reshape(-1).tolist(),
            userface=np.asarray(faces, np.int32).reshape(-1).tolist(),
        )
        body.add_geom(
            name=f"{object_body_name(i)}_part_{j}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh_name,
            density=placed.density_kg_m3,
            rgba=list(placed.rgba) if look is None else [1.0, 1.0, 1.0, 1.0],
            material=material,
            friction=friction,
            condim=4,
        )


def overlapping_object_pairs(model: mujoco.MjModel, n_objects: int, depth_m: float) -> list[tuple[int, int]]:
    """(i, j), i < j: object bodies (arm_sim.world's object_i) that interpenetrate deeper than depth_m
    at the model's initial poses."""
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    contacts = data.contact[: data.ncon]
    if data.ncon == 0 or n_objects < 2:
        return []
    index = np.full(model.nbody, -1)
    index[object_body_ids(model, n_objects)] = np.arange(n_objects)
    a = index[model.body_rootid[model.geom_bodyid[contacts.geom1]]]
    b = index[model.body_rootid[model.geom_bodyid[contacts.geom2]]]
    deep = (a >= 0) & (b >= 0) & (a != b) & (contacts.dist < -depth_m)
    pairs = np.unique(np.sort(np.stack([a[deep], b[deep]], axis=1), axis=1), axis=0)
    return [(int(i), int(j)) for i, j in pairs]


def compile_without_overlap_contacts(
    spec: mujoco.MjSpec, n_objects: int, depth_m: float = OVERLAP_EXCLUDE_M
) -> tuple[mujoco.MjModel, list[tuple[int, int]]]:
    """(model, pairs): the spec compiled with a contact exclusion (kept in the spec, so in its MJCF too)
    between every two objects that interpenetrate deeper than depth_m as built. Raises ValueError when
    MuJoCo's compiler does."""
    model = spec.compile()
    pairs = overlapping_object_pairs(model, n_objects, depth_m)
    for i, j in pairs:
        spec.add_exclude(bodyname1=object_body_name(i), bodyname2=object_body_name(j))
    return (spec.compile() if pairs else model), pairs


def object_body_ids(model: mujoco.MjModel, n_objects: int) -> np.ndarray:
    return np.array([model.body(object_body_name(i)).id for i in range(n_objects)], dtype=np.int64)


def body_pose(data: mujoco.MjData, body_id: int) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = data.xmat[body_id].reshape(3, 3)
    T[:3, 3] = data.xpos[body_id]
    return T


def servo_targets(times_s, positions, current: np.ndarray, dt_s: float, started_s_ago: float = 0.0) -> np.ndarray:
    """Servo targets every dt_s from now, the first dt_s from now, (N, 8): the trajectory (times s from
    its time zero, positions (n, 8) of 7 joints + finger opening) interpolated linearly from the current
    command. started_s_ago: how long ago its time zero was (a header stamp): > 0 skips what is already
    past (all of it past: the last point), < 0 holds the current command until it starts."""
    ahead = np.asarray(times_s, dtype=np.float64) - started_s_ago
    positions = np.asarray(positions, dtype=np.float64)
    future = ahead > 1e-9
    if not future.any():
        return positions[-1:].copy()
    hold = [-started_s_ago] if started_s_ago < 0 else []
    knots_t = np.concatenate([[0.0], hold, ahead[future]])
    knots_q = np.vstack([current] * (1 + len(hold)) + [positions[future]])
    ticks = np.arange(dt_s, knots_t[-1] + 1e-9, dt_s)
    return np.stack([np.interp(ticks, knots_t, knots_q[:, k]) for k in range(knots_q.shape[1])], axis=1)


class SimWorld:
    """A simulated scene: physics, the robot's position control, and RGB-D rendering."""

    def __init__(self, scene, robot_arm: bool = True, width: int = 640, height: int = 480, fovy_deg: float = 45.0):
        self.scene = scene
        self.model = build_world(scene, robot_arm=robot_arm)
        self.data = mujoco.MjData(self.model)
        self.has_robot = robot_arm
        self.width, self.height, self.fovy_deg = width, height, fovy_deg
        self.K = intrinsics(width, height, fovy_deg)
        self.object_ids = object_body_ids(self.model, len(scene.objects))
        self._camera_id = self.model.camera(RENDER_CAMERA).id
        self.model.cam_fovy[self._camera_id] = fovy_deg
        n_geom = self.model.ngeom
        self._geom_label = np.zeros(n_geom + 1, dtype=np.uint16)  # last slot: background (-1)
        body_to_label = np.zeros(self.model.nbody, dtype=np.uint16)
        body_to_label[self.object_ids] = np.arange(1, len(self.object_ids) + 1, dtype=np.uint16)
        self._geom_label[:n_geom] = body_to_label[self.model.geom_bodyid]
        self.appearance = scene.appearance
        self._geom_dark = np.zeros(n_geom + 1, bool)
        self._geom_shiny = np.zeros(n_geom + 1, bool)
        if self.appearance is not None:
            looks = self.appearance.objects
            object_of_geom = self._geom_label[:n_geom].astype(np.int64) - 1
            on_object = object_of_geom >= 0
            self._geom_dark[:n_geom][on_object] = [looks[k].dark for k in object_of_geom[on_object]]
            self._geom_shiny[:n_geom][on_object] = [looks[k].shiny for k in object_of_geom[on_object]]
        self.artefacts = SensorArtefacts()
        self._renderer = None
        self._segmentation_renderer = None
        if robot_arm:
            self._joint_qpos = np.array([self.model.joint(n).qposadr[0] for n in robot.JOINT_NAMES])
            self._finger_qpos = np.array([self.model.joint(n).qposadr[0] for n in robot.FINGER_JOINT_NAMES])
            self._joint_dof = np.array([self.model.joint(n).dofadr[0] for n in robot.JOINT_NAMES])
            self.set_robot_state(robot.HOME_Q, robot.GRIPPER_OPEN_M)
        mujoco.mj_forward(self.model, self.data)

    # --- robot -------------------------------------------------------------------------------
    def set_robot_state(self, q, gripper_m: float) -> None:
        self.data.qpos[self._joint_qpos] = q
        self.data.qpos[self._finger_qpos] = gripper_m
        self.data.ctrl[:7] = q
        self.data.ctrl[7] = gripper_m
        mujoco.mj_forward(self.model, self.data)

    def joint_positions(self) -> np.ndarray:
        """Arm joint angles (7,) then the finger opening (m)."""
        return np.concatenate([self.data.qpos[self._joint_qpos], self.data.qpos[self._finger_qpos[:1]]])

    def joint_velocities(self) -> np.ndarray:
        return np.concatenate([self.data.qvel[self._joint_dof], [0.0]])

    def execute(self, times_s: np.ndarray, positions: np.ndarray, control_dt_s: float = SERVO_PERIOD_S) -> None:
        """Track a joint trajectory (times from now, positions (N,8): 7 joints + finger opening) with
        the position servos, interpolated every control_dt_s; physics runs in C between updates."""
        targets = servo_targets(times_s, positions, self.data.ctrl[:8].copy(), control_dt_s)
        lo, hi = self.model.actuator_ctrlrange[:8].T
        targets = np.clip(targets, lo, hi)
        substeps = max(1, int(round(control_dt_s / self.model.opt.timestep)))
        for target in targets:
            self.data.ctrl[:8] = target
            mujoco.mj_step(self.model, self.data, nstep=substeps)

    # --- physics -----------------------------------------------------------------------------
    def settle(self, seconds: float = 2.0) -> None:
        mujoco.mj_step(self.model, self.data, nstep=int(round(seconds / self.model.opt.timestep)))

    def object_poses(self) -> list[np.ndarray]:
        return [body_pose(self.data, int(b)) for b in self.object_ids]

    # --- rendering ---------------------------------------------------------------------------
    def _place_camera(self, T_world_camera: np.ndarray) -> None:
        place_camera(self.model, self.data, self._camera_id, T_world_camera)

    def render(
        self,
        T_world_camera: np.ndarray,
        noise: DepthNoise | None = None,
        rng: np.random.Generator | None = None,
        with_visibility: bool = True,
        stamp_s: float = 0.0,
    ) -> RgbdFrame:
        """RGB (uint8), depth (float32 m, noisy unless noise.enabled is False), instance labels and
        each object's visible fraction (visible pixels / pixels when rendered alone)."""
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self.height, self.width)
            flags = mujoco.mjtRndFlag
            for flag in (flags.mjRND_SHADOW, flags.mjRND_REFLECTION, flags.mjRND_SKYBOX):
                self._renderer.scene.flags[flag] = False
            self._renderer.scene.flags[flags.mjRND_SHADOW] = self.appearance is not None and self.appearance.shadows
        if self._segmentation_renderer is None:
            self._segmentation_renderer = _single_sample_renderer(self.model, self.height, self.width)
            self._segmentation_renderer.enable_segmentation_rendering()
        r = self._renderer
        self._place_camera(np.asarray(T_world_camera, dtype=np.float64))
        r.update_scene(self.data, camera=self._camera_id)
        rgb = r.render().copy()
        r.enable_depth_rendering()
        depth = r.render().astype(np.float32)
        r.disable_depth_rendering()
        self._segmentation_renderer.update_scene(self.data, camera=self._camera_id)
        seg = self._segmentation_renderer.render()
        geom = np.where(seg[..., 1] == int(mujoco.mjtObj.mjOBJ_GEOM), seg[..., 0], -1)
        labels = self._geom_label[geom]
        noise = DepthNoise() if noise is None else noise
        rng = rng if rng is not None else np.random.default_rng()
        depth = apply_depth_noise(depth, self.K, rng, noise)
        if self.appearance is not None and noise.enabled:
            depth = apply_sensor_artefacts(
                depth,
                rgb,
                self._geom_dark[geom],
                self._geom_shiny[geom],
                self.appearance.depth_shift_px,
                rng,
                self.artefacts,
            )
            rgb = apply_camera_response(rgb, sample_camera_response(rng), rng)
        visible = (
            self.visible_fractions(labels, T_world_camera) if with_visibility else np.full(len(self.object_ids), -1.0)
        )
        T = np.array(T_world_camera, float)
        return RgbdFrame(rgb, depth, self.K.copy(), T, labels, stamp_s=stamp_s, visible_fraction=visible)

    def visible_fractions(self, labels: np.ndarray, T_world_camera: np.ndarray) -> np.ndarray:
        """Visible pixels over the pixels each object covers when rendered alone (its convex parts,
        which are exactly what MuJoCo renders)."""
        counts = np.bincount(labels.ravel(), minlength=len(self.object_ids) + 1)[1:]
        fractions = np.zeros(len(self.object_ids))
        for i, (placed, T) in enumerate(zip(self.scene.objects, self.object_poses(), strict=True)):
            parts = [vertices @ T[:3, :3].T + T[:3, 3] for vertices, _ in placed.convex_parts_local()]
            alone = silhouette(parts, self.K, T_world_camera, self.width, self.height).sum()
            fractions[i] = min(1.0, counts[i] / alone) if alone > 0 else 0.0
        return fractions

    def close(self) -> None:
        for renderer in (self._renderer, self._segmentation_renderer):
            if renderer is not None:
                renderer.close()
        self._renderer = self._segmentation_renderer = None


def place_camera(model: mujoco.MjModel, data: mujoco.MjData, camera_id: int, T_world_camera: np.ndarray) -> None:
    """Moves a model's camera to the optical frame T_world_camera (x right, y down, z forward)."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, (np.asarray(T_world_camera, dtype=np.float64)[:3, :3] @ OPTICAL_TO_MUJOCO).reshape(9))
    model.cam_pos[camera_id] = T_world_camera[:3, 3]
    model.cam_quat[camera_id] = quat
    mujoco.mj_camlight(model, data)


def _single_sample_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A renderer without multisampling, for segmentation: with it, some drivers (NVIDIA's EGL) blend
    the id colours of neighbouring geoms at their edges into ids that exist nowhere."""
    samples = model.vis.quality.offsamples
    model.vis.quality.offsamples = 0
    try:
        return mujoco.Renderer(model, height, width)
    finally:
        model.vis.quality.offsamples = samples
