"""The planner's MuJoCo twin: reconstructed objects + table + robot, built by arm_sim's world builder.

Objects arrive as (id, T_world_object, mesh, convex parts) in the object frame. Objects without
convex parts are decomposed here (arm_reconstruction's plane-split decomposer, the convex hull as
fallback). Degenerate parts are dropped; an object left without usable geometry is skipped and
reported. Two reconstructed objects that overlap as built (a hidden side completed into its
neighbour) do not collide with each other: pressed apart by the solver they never rest, and their
contacts made a cluttered twin several times slower. The model is rebuilt only when the set of object
geometries changes; new poses of the same objects only change the twin's initial state.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import mujoco
import numpy as np
import trimesh

from arm_planner.finger_clearance import halfspaces
from arm_planner.mppi import STATE_SPEC
from arm_planner.robot_spec import RobotSpec
from arm_planner.tasks.base import TargetGeometry
from arm_reconstruction.convex_parts import ConvexDecomposer, DecompositionSettings
from arm_reconstruction.metrics import sample_surface_points
from arm_sim import robot as sim_robot
from arm_sim.objects import ObjectModel
from arm_sim.scenes import PlacedObject, Scene
from arm_sim.world import (
    OVERLAP_EXCLUDE_M,
    ROBOT_BASE_XY,
    SLIDING_FRICTION,
    compile_without_overlap_contacts,
    object_body_name,
    world_spec,
)

MIN_PART_VOLUME_M3 = 1e-10
MIN_EXTENT_M = 0.0005
MAX_DECOMPOSITION_PARTS = 8
MAX_GEOMETRY_VERTICES = 400
# Points sampled over a target's convex parts, so that what lies along a line through it is known
# between its vertices (a box's faces carry none).
TARGET_SURFACE_SAMPLES = 800
# Objects overlapping deeper than this as built (m) do not collide with each other in the twin.


def stabilize_servos(model: mujoco.MjModel, max_step_frequency: float = 0.5) -> None:
    """Raise the armature of servo-driven dofs so that timestep * natural frequency <= the bound.

    A position servo with gain kp on inertia I rings at w = sqrt(kp / I); with the twin's coarse
    physics step the stiff distal joints and fingers (w * dt > 1) go unstable and grasps slip.
    Adding armature I >= kp * dt^2 / bound^2 keeps them stable; the servos are overdamped, so their
    slow (tracking) pole kp / kv and their force limits, hence the trajectory, barely change.
    Dofs coupled by a joint equality (the two fingers) get the same armature.
    """
    dt = model.opt.timestep
    for a in range(model.nu):
        if model.actuator_trntype[a] != mujoco.mjtTrn.mjTRN_JOINT:
            continue
        dof = model.jnt_dofadr[model.actuator_trnid[a, 0]]
        needed = float(model.actuator_gainprm[a, 0]) * dt * dt / max_step_frequency**2
        model.dof_armature[dof] = max(model.dof_armature[dof], needed)
    for e in range(model.neq):
        if model.eq_type[e] == mujoco.mjtEq.mjEQ_JOINT:
            d1, d2 = model.jnt_dofadr[model.eq_obj1id[e]], model.jnt_dofadr[model.eq_obj2id[e]]
            model.dof_armature[[d1, d2]] = model.dof_armature[[d1, d2]].max()


class TwinError(RuntimeError):
    """The twin could not be built (bad geometry, model compilation failure)."""


@dataclass
class TwinObject:
    """One object for the twin; vertices of mesh and convex_parts are in the object frame (metres)."""

    id: int
    T_world_object: np.ndarray
    mesh: trimesh.Trimesh | None
    convex_parts: list[trimesh.Trimesh] = field(default_factory=list)
    visible_fraction: float = -1.0
    method: str = ""


def panda_robot_spec() -> RobotSpec:
    """The arm_sim robot: 7 Panda joints with position servos, one gripper servo (finger opening, m)."""
    return RobotSpec(
        arm_joints=tuple(sim_robot.JOINT_NAMES),
        gripper_actuator=sim_robot.ACTUATOR_NAMES[-1],
        gripper_open=float(sim_robot.GRIPPER_OPEN_M),
        gripper_closed=0.0,
        tcp_body=sim_robot.HAND_NAME,
        tcp_offset_m=(0.0, 0.0, float(sim_robot.TCP_OFFSET_M)),
        max_joint_rate_rad_s=1.5,
        max_gripper_rate=0.1,
        trajectory_joint_names=tuple(sim_robot.JOINT_NAMES) + (sim_robot.FINGER_JOINT_NAMES[0],),
        finger_gap_open_m=float(sim_robot.FINGER_GAP_OPEN_M),
        fingertip_to_palm_m=float(sim_robot.FINGERTIP_TO_PALM_M),
        tcp_above_fingertip_m=float(sim_robot.TCP_ABOVE_FINGERTIP_M),
        finger_thickness_m=2 * float(sim_robot.FINGER_HALF_SIZE_M[1]),
        finger_width_m=2 * float(sim_robot.FINGER_HALF_SIZE_M[0]),
    )


def _valid_hull(vertices: np.ndarray) -> trimesh.Trimesh | None:
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    vertices = vertices[np.all(np.isfinite(vertices), axis=1)]
    if len(vertices) < 4 or np.min(np.ptp(vertices, axis=0)) < MIN_EXTENT_M:
        return None
    try:
        hull = trimesh.convex.convex_hull(vertices)
    except Exception:  # qhull raises on coplanar / degenerate input
        return None
    if hull.volume < MIN_PART_VOLUME_M3 or len(hull.faces) < 4:
        return None
    return hull


def decompose(mesh: trimesh.Trimesh, max_parts: int = MAX_DECOMPOSITION_PARTS) -> list[trimesh.Trimesh]:
    """Convex parts of a watertight mesh by arm_reconstruction's fast plane-split decomposer."""
    global _DECOMPOSER
    if _DECOMPOSER is None:
        _DECOMPOSER = ConvexDecomposer(DecompositionSettings(max_parts=max_parts))
    return _DECOMPOSER(mesh)


_DECOMPOSER = None


def usable_parts(obj: TwinObject, decompose_missing: bool = True) -> list[trimesh.Trimesh]:
    """Convex hulls of the object's parts; decomposes its mesh when it arrives without parts."""
    parts = [h for h in (_valid_hull(p.vertices) for p in obj.convex_parts) if h is not None]
    if parts or obj.mesh is None or len(obj.mesh.vertices) == 0:
        return parts
    if decompose_missing and obj.mesh.is_watertight and len(obj.mesh.faces) >= 4:
        try:
            parts = [h for h in (_valid_hull(p.vertices) for p in decompose(obj.mesh)) if h is not None]
        except Exception:  # a decomposition failure falls back to the hull below
            parts = []
    if not parts:
        hull = _valid_hull(obj.mesh.vertices)
        parts = [hull] if hull is not None else []
    return parts


def geometry_signature(objects: list[TwinObject], table_height_m: float) -> str:
    """Hash of ids and geometry (not poses): the twin must be rebuilt iff this changes."""
    h = hashlib.sha256(np.float64(table_height_m).tobytes())
    for obj in objects:
        h.update(np.int64(obj.id).tobytes())
        for part in obj.convex_parts:
            h.update(np.ascontiguousarray(part.vertices, dtype=np.float64).tobytes())
        if obj.mesh is not None:
            h.update(np.ascontiguousarray(obj.mesh.vertices, dtype=np.float64).tobytes())
    return h.hexdigest()


class Twin:
    """A compiled twin model with a map from object id to its body, plus the robot spec.
    friction: the object-table sliding friction coefficient the twin assumes."""

    def __init__(
        self,
        objects: list[TwinObject],
        table_height_m: float = 0.0,
        timestep_s: float = 0.01,
        robot: RobotSpec | None = None,
        overlap_exclude_m: float = OVERLAP_EXCLUDE_M,
        friction: float = SLIDING_FRICTION,
        robot_base_xy=ROBOT_BASE_XY,
    ):
        if not np.isfinite(table_height_m):
            raise TwinError("table height is not finite")
        if not np.isfinite(friction) or friction <= 0.0:
            raise TwinError(f"friction must be a positive number, got {friction}")
        self.robot = robot or panda_robot_spec()
        self.table_height_m = float(table_height_m)
        self.skipped: dict[int, str] = {}
        placed, self.objects = [], []
        for obj in objects:
            T = np.asarray(obj.T_world_object, dtype=np.float64)
            if T.shape != (4, 4) or not np.all(np.isfinite(T)):
                self.skipped[obj.id] = "pose is not a finite 4x4 transform"
                continue
            parts = usable_parts(obj)
            if not parts:
                self.skipped[obj.id] = "mesh is empty or degenerate (no convex part with volume)"
                continue
            mesh = obj.mesh if obj.mesh is not None and len(obj.mesh.vertices) else trimesh.util.concatenate(parts)
            model = ObjectModel(f"recon_{obj.id}", "reconstructed", mesh, parts)
            placed.append(PlacedObject(model, 1.0, T, (0.6, 0.6, 0.6, 1.0)))
            self.objects.append(obj)
        base_xy = tuple(float(v) for v in robot_base_xy)
        self.scene = Scene(placed, self.table_height_m, friction=float(friction), robot_base_xy=base_xy)
        try:
            spec = world_spec(self.scene, robot_arm=True, timestep_s=timestep_s, name="arm_twin")
            self.model, self.overlapping = compile_without_overlap_contacts(spec, len(placed), overlap_exclude_m)
        except Exception as exc:  # mujoco raises ValueError with the compiler's message
            raise TwinError(f"twin failed to compile: {exc}") from exc
        stabilize_servos(self.model)
        self.body_names = {obj.id: object_body_name(i) for i, obj in enumerate(self.objects)}
        self.signature = geometry_signature(objects, table_height_m)
        self._data = mujoco.MjData(self.model)
        self._part_halfspaces: list[list[np.ndarray]] | None = None
        self._surface_points: dict[int, np.ndarray] = {}  # object index -> points, object frame

    def __contains__(self, object_id: int) -> bool:
        return object_id in self.body_names

    def body_name(self, object_id: int) -> str:
        return self.body_names[object_id]

    def _vertices_world(self, i: int, T_world_object: np.ndarray) -> np.ndarray:
        """Object i's convex parts' vertices (at most MAX_GEOMETRY_VERTICES) at T_world_object."""
        vertices = np.concatenate([p.vertices for p in self.scene.objects[i].model.convex_parts])
        if len(vertices) > MAX_GEOMETRY_VERTICES:
            vertices = vertices[np.linspace(0, len(vertices) - 1, MAX_GEOMETRY_VERTICES).astype(int)]
        return vertices @ T_world_object[:3, :3].T + T_world_object[:3, 3]

    def _surface_points_world(self, i: int, T_world_object: np.ndarray) -> np.ndarray:
        """TARGET_SURFACE_SAMPLES points over object i's convex parts (by area) at T_world_object."""
        if i not in self._surface_points:
            parts = trimesh.util.concatenate(list(self.scene.objects[i].model.convex_parts))
            try:
                self._surface_points[i] = sample_surface_points(parts, TARGET_SURFACE_SAMPLES, seed=i)
            except ValueError:  # parts without area: the vertices stand for the surface
                self._surface_points[i] = np.zeros((0, 3))
        return self._surface_points[i] @ T_world_object[:3, :3].T + T_world_object[:3, 3]

    def _halfspaces_world(self, i: int, T_world_object: np.ndarray) -> list[np.ndarray]:
        """Object i's convex parts as half-spaces (finger_clearance.halfspaces) at T_world_object."""
        if self._part_halfspaces is None:
            self._part_halfspaces = [[halfspaces(p) for p in o.model.convex_parts] for o in self.scene.objects]
        R, t = T_world_object[:3, :3], T_world_object[:3, 3]
        out = []
        for planes in self._part_halfspaces[i]:
            normals = planes[:, :3] @ R.T
            out.append(np.column_stack([normals, planes[:, 3] - normals @ t]))
        return out

    def target_geometry(
        self, object_id: int, poses: dict[int, np.ndarray] | None = None, with_halfspaces: bool = True
    ) -> TargetGeometry:
        """The target's vertices, convex parts and centre of mass in the world and the other objects'
        vertices and (if with_halfspaces) convex parts, with objects at `poses` (object id ->
        T_world_object; objects not in it: as built)."""
        poses = poses or {}
        geometry = None
        obstacles, obstacle_halfspaces = [], []
        for i, (other_id, placed) in enumerate(zip(self.body_names, self.scene.objects, strict=True)):
            T = np.asarray(poses.get(other_id, placed.T_world_object), dtype=np.float64)
            vertices_world = self._vertices_world(i, T)
            if other_id != object_id:
                obstacles.append(vertices_world)
                if with_halfspaces:
                    obstacle_halfspaces += self._halfspaces_world(i, T)
                continue
            com_world = T[:3, :3] @ self.model.body(self.body_names[object_id]).ipos + T[:3, 3]
            geometry = TargetGeometry(com_world, vertices_world, self.table_height_m, T[:3, :3].copy())
            geometry.part_halfspaces = self._halfspaces_world(i, T)
            geometry.surface_points_world = self._surface_points_world(i, T)
        if geometry is None:
            raise KeyError(f"object {object_id} is not in the twin")
        if obstacles:
            geometry.obstacle_vertices_world = np.concatenate(obstacles)
        geometry.obstacle_halfspaces = obstacle_halfspaces
        return geometry

    def initial_state(
        self,
        arm_q: np.ndarray,
        gripper_opening_m: float,
        poses: dict[int, np.ndarray] | None = None,
    ) -> np.ndarray:
        """State vector (STATE_SPEC) with the robot at arm_q / opening and objects at their poses."""
        model, data = self.model, self._data
        mujoco.mj_resetData(model, data)
        robot = self.robot.resolve(model)
        data.qpos[robot.qpos_adr] = arm_q
        for name in sim_robot.FINGER_JOINT_NAMES:
            data.qpos[model.joint(name).qposadr[0]] = gripper_opening_m
        for obj_id, T in (poses or {}).items():
            if obj_id not in self.body_names:
                continue
            joint = model.body(self.body_names[obj_id]).jntadr[0]
            adr = model.jnt_qposadr[joint]
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, np.asarray(T, dtype=np.float64)[:3, :3].reshape(9))
            data.qpos[adr : adr + 3] = np.asarray(T)[:3, 3]
            data.qpos[adr + 3 : adr + 7] = quat
        data.ctrl[robot.arm_actuators] = arm_q
        data.ctrl[robot.gripper_actuator] = gripper_opening_m
        mujoco.mj_forward(model, data)
        state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
        mujoco.mj_getState(model, data, state, STATE_SPEC)
        return state
