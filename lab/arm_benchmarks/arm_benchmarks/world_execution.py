"""Running plans in the ground-truth world (arm_sim's SimWorld) for the manipulation benchmark.

Open loop (the paper's protocol): one plan from the first view, executed afterwards to its end.
Closed loop: every control step the planner executes in its twin also runs in the world, and every
`period_steps` steps the twin's state is replaced by an observation of the world: the robot's joint
positions and velocities, and each object's pose from a perfect tracker (the object's true rigid
motion since the view, applied to the method's own mesh; shapes stay the method's reconstruction),
or, with a `Reobservation`, from a new depth frame of the world through the first view's camera
(depth_tracking: the method's mesh fitted to the object's pixels; an object out of view keeps the
twin's prediction). Same step budget as open loop. In a perturbed world (world_perturbation) the
robot's servos hold each command the draw's latency late and off by its joint offsets, and its
encoders report the joints off by the same offsets (what the robot believes it commanded).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from arm_benchmarks.depth_tracking import DepthTracker, rotation_vector
from arm_benchmarks.world_perturbation import PerturbedDraw
from arm_planner.session import ManipulationSession, Outcome
from arm_planner.tasks import GRASP_LIFT_M, TASK_GRASP
from arm_planner.twin import TwinObject
from arm_sim import robot

HOLD_AFTER_S = 0.5


@dataclasses.dataclass
class WorldRun:
    """The world's verdict (task met, error m) on a plan and the plan's outcome in the twin."""

    success: bool
    error_m: float
    outcome: Outcome
    observations: int = 0


def task_outcome(task: str, start: np.ndarray, end: np.ndarray, goal_displacement_m, tolerance_m: float):
    """(met, error m) of the target's centre moving from start to end (world, m)."""
    if task == TASK_GRASP:
        lift = float(end[2] - start[2])
        return lift >= GRASP_LIFT_M, max(0.0, GRASP_LIFT_M - lift)
    error = float(np.linalg.norm(end - (start + np.asarray(goal_displacement_m))))
    return error <= tolerance_m, error


@dataclasses.dataclass
class Reobservation:
    """Where the closed loop's object poses come from instead of the perfect tracker: frames of the
    world rendered through T_world_camera with the world's depth noise (arm_sim DepthNoise or None
    for its default) and rng, fitted by the tracker."""

    T_world_camera: np.ndarray
    tracker: DepthTracker
    noise: object = None
    rng: np.random.Generator | None = None
    fitted: int = 0
    kept: int = 0


def tracked_pose(T_view_true: np.ndarray, T_now_true: np.ndarray, T_view_method: np.ndarray) -> np.ndarray:
    """The method's object pose moved by the true object's rigid motion since the view."""
    return T_now_true @ np.linalg.inv(T_view_true) @ T_view_method


class WorldSync:
    """Planner `observe` hook: executes each control step in the world and, every `period_steps`,
    writes the world's robot state and tracked object poses and velocities into the twin. With a
    `perturbation`, the world's robot is late and off as the draw says."""

    def __init__(
        self,
        session: ManipulationSession,
        world,
        objects: list[TwinObject],
        period_steps: int,
        reobserve=None,
        perturbation: PerturbedDraw | None = None,
    ):
        self.session, self.world, self.period = session, world, int(period_steps)
        self.perturbation = perturbation
        arm = len(robot.JOINT_NAMES)
        self._commands = [world.data.ctrl[: arm + 1].copy()]  # planned commands, the one held at the start first
        if perturbation is not None:
            self._commands[0][:arm] -= perturbation.joint_offsets_rad
        self.reobserve: Reobservation | None = reobserve
        self._last_fit: dict[int, tuple[float, np.ndarray]] = {}
        self.control_dt_s = session.config.mppi.control_dt_s
        self.objects = {o.id: o for o in objects}
        self.poses_at_view = world.object_poses()
        self.joint_names = tuple(robot.JOINT_NAMES) + tuple(robot.FINGER_JOINT_NAMES)
        self.actuators = None
        self.observations = 0

    def _servo_command(self, step: int, command: np.ndarray) -> np.ndarray:
        """What the world's servos hold at the end of control step `step` for the planned `command`
        (7 joints + finger): unperturbed, the command itself; perturbed, the planned commands
        interpolated `latency_s` earlier, the arm joints off by their offsets."""
        self._commands.append(np.asarray(command, dtype=np.float64).copy())
        if self.perturbation is None:
            return self._commands[-1]
        at = max(step + 1 - self.perturbation.latency_s / self.control_dt_s, 0.0)  # index into _commands
        below = int(np.floor(at))
        above = min(below + 1, len(self._commands) - 1)
        return self.held(self._commands[below] + (at - below) * (self._commands[above] - self._commands[below]))

    def held(self, command: np.ndarray) -> np.ndarray:
        """What the world's servos hold for a command kept unchanged (7 joints + finger): the command,
        the arm joints off by the draw's offsets when perturbed (the robot's calibration error stays
        when the plan ends)."""
        held = np.asarray(command, dtype=np.float64).copy()
        if self.perturbation is not None:
            held[: len(robot.JOINT_NAMES)] += self.perturbation.joint_offsets_rad
        return held

    def _encoder_offsets(self) -> np.ndarray:
        """Per robot joint, what the encoders report minus the truth (rad; 0 for the finger)."""
        offsets = np.zeros(len(self.joint_names))
        if self.perturbation is not None:
            offsets[: len(robot.JOINT_NAMES)] = -self.perturbation.joint_offsets_rad
        return offsets

    @staticmethod
    def _free_joint(model, name: str) -> tuple[int, int]:
        joint = model.body(name).jntadr[0]
        return model.jnt_qposadr[joint], model.jnt_dofadr[joint]

    def _set_free_body(self, model, data, name: str, T: np.ndarray, v_world: np.ndarray, omega_world: np.ndarray):
        """A twin object's free joint set to pose T (4x4 world), its origin's velocity v_world (m/s) and
        angular velocity omega_world (rad/s, world frame)."""
        qadr, vadr = self._free_joint(model, name)
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, np.ascontiguousarray(T[:3, :3]).reshape(9))
        data.qpos[qadr : qadr + 7] = np.concatenate([T[:3, 3], quat])
        data.qvel[vadr : vadr + 3] = v_world
        data.qvel[vadr + 3 : vadr + 6] = T[:3, :3].T @ omega_world  # free joint: body-frame angular velocity

    def _set_object(self, model, data, name: str, world_body: int, T_twin: np.ndarray) -> None:
        w = self.world
        wjoint = w.model.body_jntadr[world_body]
        wv = w.data.qvel[w.model.jnt_dofadr[wjoint] : w.model.jnt_dofadr[wjoint] + 6]
        omega = w.data.xmat[world_body].reshape(3, 3) @ wv[3:]
        v = wv[:3] + np.cross(omega, T_twin[:3, 3] - w.data.xpos[world_body])
        self._set_free_body(model, data, name, T_twin, v, omega)

    def _twin_pose(self, model, data, name: str) -> np.ndarray:
        qadr, _ = self._free_joint(model, name)
        T = np.eye(4)
        R = np.zeros(9)
        mujoco.mju_quat2Mat(R, data.qpos[qadr + 3 : qadr + 7])
        T[:3, :3], T[:3, 3] = R.reshape(3, 3), data.qpos[qadr : qadr + 3]
        return T

    def _reobserve(self, model, data) -> None:
        """Object poses fitted to a new frame; velocities from the change since the object's last fit."""
        r, names = self.reobserve, self.session.twin.body_names
        predicted = {object_id: self._twin_pose(model, data, name) for object_id, name in names.items()}
        frame = self.world.render(r.T_world_camera, noise=r.noise, rng=r.rng, with_visibility=False)
        fitted = r.tracker.track(frame.depth_m, frame.labels, frame.K, r.T_world_camera, predicted)
        now_s = (self.observations + 1) * self.period * self.control_dt_s
        for object_id, T in fitted.items():
            v, omega = np.zeros(3), np.zeros(3)
            if object_id in self._last_fit:
                then_s, T_then = self._last_fit[object_id]
                dt = max(now_s - then_s, 1e-6)
                v = (T[:3, 3] - T_then[:3, 3]) / dt
                omega = rotation_vector(T[:3, :3] @ T_then[:3, :3].T) / dt
            self._set_free_body(model, data, names[object_id], T, v, omega)
            self._last_fit[object_id] = (now_s, T)
        r.fitted += len(fitted)
        r.kept += len(predicted) - len(fitted)

    def __call__(self, step: int, control: np.ndarray, model, data) -> bool:
        if self.actuators is None:
            self.actuators = self.session.planner.robot.actuators
        self.world.execute(np.array([self.control_dt_s]), self._servo_command(step, control[self.actuators])[None])
        if (step + 1) % self.period:
            return False
        w = self.world
        for name, offset in zip(self.joint_names, self._encoder_offsets(), strict=True):
            twin_joint, world_joint = model.joint(name), w.model.joint(name)
            data.qpos[twin_joint.qposadr[0]] = w.data.qpos[world_joint.qposadr[0]] + offset
            data.qvel[twin_joint.dofadr[0]] = w.data.qvel[world_joint.dofadr[0]]
        if self.reobserve is not None:
            self._reobserve(model, data)
            self.observations += 1
            return True
        poses_now = w.object_poses()
        for object_id, body_name in self.session.twin.body_names.items():
            n = object_id - 1
            T_twin = tracked_pose(self.poses_at_view[n], poses_now[n], self.objects[object_id].T_world_object)
            self._set_object(model, data, body_name, int(w.object_ids[n]), T_twin)
        self.observations += 1
        return True


def run_in_world(
    session: ManipulationSession,
    world,
    objects: list[TwinObject],
    table_height_m: float,
    target_index: int,
    task: str,
    goal_displacement_m,
    tolerance_m: float,
    period_steps: int = 0,
    reobserve: Reobservation | None = None,
    perturbation: PerturbedDraw | None = None,
) -> WorldRun:
    """Plan on `objects` and execute in `world` (a SimWorld of the true scene, robot at home);
    period_steps 0 = open loop; reobserve: object poses from new frames instead of the perfect
    tracker (closed loop only); perturbation: the world's robot late and off as drawn (closed loop
    only). Object id n is the world's object n - 1."""
    body = world.object_ids[target_index]
    start = world.data.xipos[body].copy()
    session.set_objects(objects, table_height_m)
    if perturbation is not None and period_steps <= 0:
        raise ValueError("a perturbed robot runs closed loop here; open loop, use world_perturbation.execute_perturbed")
    sync = WorldSync(session, world, objects, period_steps, reobserve, perturbation) if period_steps > 0 else None
    outcome = session.request(
        task,
        target_index + 1,
        goal_displacement_m,
        tolerance_m,
        robot.HOME_Q,
        robot.GRIPPER_OPEN_M,
        observe=sync,
    )
    if not outcome.planned:
        return WorldRun(False, float("nan"), outcome)
    result = outcome.result
    if sync is None:
        world.execute(result.times_s, result.joint_positions)
    last = result.joint_positions[-1] if sync is None else sync.held(result.joint_positions[-1])
    world.execute(np.array([HOLD_AFTER_S]), last[None])
    met, error = task_outcome(task, start, world.data.xipos[body].copy(), goal_displacement_m, tolerance_m)
    return WorldRun(met, error, outcome, sync.observations if sync else 0)
