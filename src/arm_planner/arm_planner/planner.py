"""plan(task, target, goal) in a MuJoCo twin -> joint trajectory + predicted outcome.

The executed plan is built the paper's way: every MPPI step optimises the next `horizon` control
steps from the twin's current state, the first control is applied to the twin for one control step
(0.02 s), and the task's state machine advances on that executed state.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from arm_core.settings import setting
from arm_planner.finger_clearance import OpenFingers
from arm_planner.kinematics import BodyKinematics
from arm_planner.mppi import (
    STATE_SPEC,
    ControlLimits,
    Mppi,
    MppiConfig,
    PathBudget,
    free_body_trees,
    get_state,
    linear_speed_cap,
    set_sleep,
    state_layout,
)
from arm_planner.replay import ReplayConfig, ReplayOutcome, replay_in_perturbed_twins
from arm_planner.robot_spec import ResolvedRobot, RobotSpec
from arm_planner.tasks import TASKS
from arm_planner.tasks.base import RewardWeights, TargetGeometry, TaskSetup
from arm_planner.tasks.registry import TASK_REWARDS
from arm_sim.world import OVERLAP_EXCLUDE_M, SLIDING_FRICTION

DEFAULT_TOLERANCE_M = 0.025


@dataclass
class PlanRequest:
    task: str
    target_body: str
    goal_displacement_m: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tolerance_m: float = DEFAULT_TOLERANCE_M
    # Re-planning: the target's centre of mass when the task was first requested (world, m); goals stay
    # anchored there. None = the target's current centre in the twin.
    start_com_world: np.ndarray | None = None
    # Re-planning: task state reached so far ("grasping", "grasped", "pushing") and steps spent in it.
    resume_state: str | None = None
    resume_steps_in_state: int = 0


@dataclass
class NoiseConfig:
    """Sampling noise on the target rates: TCP velocity std mapped through the arm Jacobian + joint std."""

    linear_std_m_s: float = 0.3
    angular_std_rad_s: float = 0.5
    joint_std_rad_s: float = 0.05
    damping: float = 0.05


@dataclass
class PlannerConfig:
    """The planner's settings (docs/experiments.md has the figures behind each default)."""

    mppi: MppiConfig = field(default_factory=MppiConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    # An open-loop plan that met the task is replayed in perturbed twins (replay.py).
    replay: ReplayConfig = field(default_factory=ReplayConfig)
    weights: RewardWeights = field(default_factory=RewardWeights)
    close_steps: int = setting(75, "Grasp: steps the gripper closes for (paper: 75)", 1, 1000)
    grasp_lift_goal_m: float = setting(0.10, "Grasp: the lift the reward aims for, m (success: 0.05)", 0.05, 0.5)
    rearrange_carry_height_m: float = setting(0.04, "Rearrange: least carry height above the goal, m", 0.0, 0.5)
    # A rearrange is a grasp (75 closing steps) and a 28 cm carry, which does not fit the paper's
    # 200 steps of 0.02 s; a caging push advances 3-5 cm/s and needs room to brake and correct.
    rearrange_steps: int = setting(500, "Rearrange: step budget (0: steps)", 0, 5000)
    push_steps: int = setting(750, "Push: step budget (0: steps)", 0, 5000)
    # Resting objects do no collision work until touched (mppi.set_sleep).
    sleep_objects: bool = setting(True, "Twin: resting objects sleep until touched")
    # Real-time planning: paths per step adapt so that a step's wall time stays within this factor of
    # control_dt_s (mppi.PathBudget). Outcomes then depend on the machine's load: benchmarks plan
    # with 0, a fixed path count.
    realtime_factor: float = setting(
        0.9,
        "Planning wall time per planned motion time the path count adapts to (0: always num_paths)",
        0.0,
        100.0,
        parameter=True,
    )
    min_paths: int = setting(8, "Fewest paths per step when planning in real time", 2, 1000)
    settle_s: float = setting(0.3, "Twin: settling with the robot still before planning, s", 0.0, 5.0, parameter=True)
    # The camera saw the target at rest: where its reconstruction falls over while the twin settles,
    # a plan grasps or pushes where the object is not (the bench_real stability criterion).
    rest_check_s: float = setting(1.0, "Twin: how long the target must rest with the robot still, s", 0.0, 10.0)
    settle_motion_m: float = setting(
        0.02, "Twin: refuse a target that moves more than this in rest_check_s, m", 0.0, float("inf")
    )
    settle_turn_deg: float = setting(
        15.0, "Twin: refuse a target that turns more than this in rest_check_s, degrees", 0.0, 180.0
    )
    twin_overlap_exclude_m: float = setting(
        OVERLAP_EXCLUDE_M, "Twin: objects overlapping deeper than this as built do not collide, m", 0.0, float("inf")
    )
    done_hold_steps: int = setting(
        10, "Stop once the predicted outcome met the task this many steps (0: never)", 0, 1000
    )
    # Tighter than the task's tolerance: margin against twin/world mismatch.
    done_goal_distance_m: float = setting(0.01, "... and the target is this near the reward's goal, m", 0.0, 1.0)
    # Uncapped, the hand slid top-heavy objects at up to 0.75 m/s and they tipped over.
    push_hand_speed_m_s: float = setting(
        0.2, "Push: the hand's top speed at and near the object, m/s (0: no cap)", 0.0, 2.0
    )
    # Faster, a held object swings about the fingers' closing axis and drops.
    carry_hand_speed_m_s: float = setting(
        0.2, "Rearrange: the hand's top speed while it holds the object, m/s (0: no cap)", 0.0, 2.0
    )
    carry_closing_along: bool = setting(True, "Rearrange: close the fingers along the carry when the object fits")
    clear_fingers: bool = setting(True, "Grasp: turn the closing axis where a finger would land on another object")
    grasp_site_search: bool = setting(
        True, "Grasp: move the grasp to where the target's material lies between the fingers (rings, U shapes)"
    )
    push_ungraspable: bool = setting(True, "Rearrange: push a target wider than the open fingers along every axis")
    push_contact_height_m: float = setting(
        0.018, "Push: the hand's contact height above the object's bottom, m (at most half its height)", 0.0, 0.2
    )
    push_cage: bool = setting(True, "Push: the open fingers fore and aft of an object that fits between them")
    # 3 mm: wine glasses and T-shapes leaned onto the front finger; -2 mm holds them upright.
    push_cage_margin_m: float = setting(
        -0.002, "Push: the cage's clearance each side, m (negative: the fingers close onto the object)", -0.01, 0.02
    )
    object_friction: float = setting(
        SLIDING_FRICTION, "Twin: object-table sliding friction (set the real table's)", 0.05, 2.0, parameter=True
    )

    @property
    def uses_hand_geometry(self) -> bool:
        """Whether grasps use the open fingers' (and palm's) sizes and the objects' convex parts."""
        return self.clear_fingers or self.grasp_site_search


@dataclass
class PlanResult:
    success: bool
    message: str
    final_error_m: float
    times_s: np.ndarray
    controls: np.ndarray
    joint_names: tuple[str, ...]
    joint_positions: np.ndarray
    states: list[str]
    step_ms: np.ndarray
    # CPU time per step summed over all threads of the process (rollout workers included), ms.
    step_cpu_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))
    # Paths sampled per step.
    step_paths: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    # Planning stopped early: the task was met and held for done_hold_steps in the twin.
    held: bool = False
    # An open-loop plan that met the task, replayed in perturbed twins (none for closed-loop plans).
    replays: ReplayOutcome = field(default_factory=lambda: ReplayOutcome(0, 0))


Feedback = Callable[[int, int, str, float], None]
# Closed loop: called after every executed control step with (step, control, twin model, twin data);
# returns True when it overwrote the twin's qpos/qvel with an observation of the real state.
Observe = Callable[[int, np.ndarray, mujoco.MjModel, mujoco.MjData], bool]
# Receding horizon: called with the trajectory joints' targets of every executed control step, as it is
# planned (see streaming.TrajectoryStream).
Stream = Callable[[np.ndarray], None]


def resume_point(states: list[str], executed_steps: int) -> tuple[str, int]:
    """(task state, steps spent in it) after the first `executed_steps` steps of a plan: where a
    re-plan from the executed prefix continues."""
    prefix = states[:executed_steps]
    state = prefix[-1]
    steps_in_state = next((i for i, s in enumerate(reversed(prefix)) if s != state), len(prefix))
    return state, steps_in_state


def settled_motion(seen_pos: np.ndarray, seen_rot: np.ndarray, body) -> tuple[float, float]:
    """(distance m, turn degrees) of a body from where it was seen (world position, rotation matrix)."""
    rotation = body.xmat.reshape(3, 3) @ seen_rot.T
    turn = np.degrees(np.arccos(np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)))
    return float(np.linalg.norm(body.xpos - seen_pos)), float(turn)


class Planner:
    """MPPI planner bound to one compiled twin model (rebuild it when the twin changes)."""

    def __init__(self, model: mujoco.MjModel, robot: RobotSpec, config: PlannerConfig | None = None):
        self.config = config or PlannerConfig()
        cfg = self.config.mppi
        self.model = model
        self.robot: ResolvedRobot = robot.resolve(model)
        self.limits = ControlLimits.from_model(model, self.robot.max_rate)
        self.mppi = Mppi(model, cfg, self.limits)
        self.qpos_offset, _ = state_layout(model)
        self.hand = BodyKinematics(model, self.robot.tcp_body, np.asarray(robot.tcp_offset_m))
        self._data = mujoco.MjData(model)
        self._object_trees = free_body_trees(model)
        free = [j for j in range(model.njnt) if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        self._object_qpos = np.array([model.jnt_qposadr[j] + k for j in free for k in range(7)], dtype=int)
        self._object_dofs = np.array([model.jnt_dofadr[j] + k for j in free for k in range(6)], dtype=int)
        self._object_qpos_trees = np.repeat(model.body_treeid[model.jnt_bodyid[free]], 7) if free else np.zeros(0, int)

    def close(self) -> None:
        self.mppi.close()

    def _stop_creeping(self, data: mujoco.MjData) -> bool:
        """Zero the velocity of objects creeping slower than 2 cm/s and 0.2 rad/s (contact jitter);
        True when it zeroed any.

        Such an object would otherwise stay awake and wake every object it touches in every rollout;
        at rest it sleeps until something pushes it.
        """
        if len(self._object_dofs) == 0:
            return False
        qvel = data.qvel[self._object_dofs].reshape(-1, 6)
        creeping = (np.linalg.norm(qvel[:, :3], axis=1) < 0.02) & (np.linalg.norm(qvel[:, 3:], axis=1) < 0.2)
        creeping &= np.any(qvel != 0.0, axis=1)
        if not creeping.any():
            return False
        qvel[creeping] = 0.0
        data.qvel[self._object_dofs] = qvel.reshape(-1)
        return True

    def _sleeping_poses_as_rest(self, data: mujoco.MjData) -> None:
        """Objects asleep in the executed twin `data` start asleep in every rollout too: an object that
        moved (a nudge, settling) and fell asleep again is at rest away from qpos0, and would otherwise
        start each rollout awake, its table contacts costing most of the physics (about half the
        rollout time in a 10-object twin)."""
        if len(self._object_qpos) == 0:
            return
        asleep = data.tree_asleep[self._object_qpos_trees] >= 0
        self.model.qpos0[self._object_qpos[asleep]] = data.qpos[self._object_qpos[asleep]]

    def _rest_objects_here(self, data: mujoco.MjData) -> None:
        """Objects at rest in `data` sleep there in the rollouts: MuJoCo initialises sleeping islands at
        qpos0, so qpos0 takes their current poses (every rollout path starts from reset data)."""
        if self.config.sleep_objects:
            self.model.qpos0[self._object_qpos] = data.qpos[self._object_qpos]
            self._stop_creeping(data)
        mujoco.mj_forward(self.model, data)

    def _reward(self, request: PlanRequest, geometry: TargetGeometry):
        target_id = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, request.target_body)
        if target_id < 0:
            raise ValueError(f"target body {request.target_body!r} not in the twin")
        target = BodyKinematics(self.model, target_id, self.model.body_ipos[target_id].copy())
        common = dict(
            hand=self.hand,
            target=target,
            geometry=geometry,
            qpos_offset=self.qpos_offset,
            arm_qpos_adr=self.robot.qpos_adr,
            arm_actuators=self.robot.arm_actuators,
            nq=self.model.nq,
            weights=self.config.weights,
        )
        joint = int(self.model.body_jntadr[target_id])
        velocity_adr = None
        if joint >= 0 and self.model.jnt_type[joint] == mujoco.mjtJoint.mjJNT_FREE:
            velocity_adr = self.qpos_offset + self.model.nq + int(self.model.jnt_dofadr[joint])
        fingers = self._open_fingers() if self.config.uses_hand_geometry else None
        setup = TaskSetup(common, self.config, self.robot.spec, fingers, velocity_adr)
        build = TASK_REWARDS.get(request.task)
        if build is None:
            raise ValueError(f"unknown task {request.task!r}; expected one of {TASKS}")
        reward = build(setup, request)
        if request.start_com_world is not None:
            reward.start_com = np.asarray(request.start_com_world, dtype=np.float64)
            reward.goal = reward.start_com + reward.goal_displacement
        if request.resume_state:
            reward.resume(request.resume_state, request.resume_steps_in_state)
        return reward

    def _open_fingers(self) -> OpenFingers:
        spec = self.robot.spec
        return OpenFingers(
            spec.finger_gap_open_m,
            spec.finger_thickness_m,
            spec.finger_width_m,
            spec.fingertip_to_palm_m,
            spec.tcp_above_fingertip_m,
        )

    def tcp_jacobian(self, data: mujoco.MjData) -> np.ndarray:
        """[6, arm joints]: the TCP's linear (m/s) then angular (rad/s) velocity per arm joint rate."""
        mujoco.mj_kinematics(self.model, data)
        mujoco.mj_comPos(self.model, data)
        jacp = np.zeros((3, self.model.nv))
        jacr = np.zeros((3, self.model.nv))
        tcp_world = data.xpos[self.robot.tcp_body] + data.xmat[self.robot.tcp_body].reshape(3, 3) @ np.asarray(
            self.robot.spec.tcp_offset_m
        )
        mujoco.mj_jac(self.model, data, jacp, jacr, tcp_world, self.robot.tcp_body)
        return np.concatenate([jacp, jacr])[:, self.robot.dof_adr]

    def noise_basis(self, data: mujoco.MjData, jac: np.ndarray | None = None) -> np.ndarray:
        """Rows: joint-space directions that move the TCP along x, y, z and rotate it, plus joint noise.
        jac: the TCP Jacobian at `data` if already computed."""
        n = self.config.noise
        jac = self.tcp_jacobian(data) if jac is None else jac
        pinv = jac.T @ np.linalg.inv(jac @ jac.T + n.damping**2 * np.eye(6))
        stds = np.array([n.linear_std_m_s] * 3 + [n.angular_std_rad_s] * 3)
        arm_rows = np.concatenate([(pinv * stds).T, n.joint_std_rad_s * np.eye(len(self.robot.arm_actuators))])
        basis = np.zeros((arm_rows.shape[0], self.model.nu))
        basis[:, self.robot.arm_actuators] = arm_rows
        return basis

    @staticmethod
    def evaluate(reward, state: np.ndarray, tolerance_m: float):
        """(met, error_m) of the task at a twin state."""
        _, _, com, _ = reward.poses(state[None])
        return reward.met(com[0], tolerance_m)

    def _motion_at_rest(self, data: mujoco.MjData, body: str, seen_pos: np.ndarray, seen_rot: np.ndarray):
        """(distance m, turn degrees) of `body` from where it was seen, once the twin in `data` (settled
        for settle_s) has run on to rest_check_s with the robot still, in a copy. A slow
        topple moves little in the settling time and then falls over while the robot approaches."""
        more = int(round((self.config.rest_check_s - self.config.settle_s) / self.model.opt.timestep))
        if more <= 0:
            return settled_motion(seen_pos, seen_rot, data.body(body))
        check = mujoco.MjData(self.model)
        mujoco.mj_copyData(check, self.model, data)
        mujoco.mj_step(self.model, check, nstep=more)
        return settled_motion(seen_pos, seen_rot, check.body(body))

    def _refused(self, message: str) -> PlanResult:
        """A result without a plan."""
        robot = self.robot
        controls = np.zeros((0, self.model.nu))
        return PlanResult(
            False, message, float("inf"), np.zeros(0), controls, robot.spec.trajectory_joint_names,
            controls[:, robot.actuators], [], np.zeros(0),
        )  # fmt: skip

    def plan(
        self,
        initial_state: np.ndarray,
        request: PlanRequest,
        geometry: TargetGeometry,
        feedback: Feedback | None = None,
        should_stop: Callable[[], bool] | None = None,
        observe: Observe | None = None,
        stream: Stream | None = None,
    ) -> PlanResult:
        """Plan from a twin state vector (STATE_SPEC); the robot starts at its qpos, gripper open.
        With `observe`, each executed step can be corrected by the real state (closed loop)."""
        cfg = self.config
        model, data, robot = self.model, self._data, self.robot
        reward = self._last_reward = self._reward(request, geometry)
        if cfg.sleep_objects:
            set_sleep(model, self._object_trees, start_asleep=False)
        mujoco.mj_resetData(model, data)
        mujoco.mj_setState(model, data, np.asarray(initial_state, dtype=np.float64), STATE_SPEC)
        ctrl = robot.control_from_joints(data.qpos[robot.qpos_adr], reward.gripper_closed, model.nu)
        data.ctrl[:] = ctrl
        initial_ctrl = ctrl.copy()
        mujoco.mj_kinematics(model, data)
        seen = data.body(request.target_body)
        seen_pos, seen_rot = seen.xpos.copy(), seen.xmat.reshape(3, 3).copy()
        mujoco.mj_step(model, data, nstep=int(round(cfg.settle_s / model.opt.timestep)))
        data.time = 0.0
        if request.resume_state is None:
            moved = self._motion_at_rest(data, request.target_body, seen_pos, seen_rot)
            if moved[0] > cfg.settle_motion_m or moved[1] > cfg.settle_turn_deg:
                return self._refused(
                    f"the target's reconstruction does not rest where the camera saw it: it moved "
                    f"{moved[0] * 100:.1f} cm and turned {moved[1]:.0f} degrees in {cfg.rest_check_s:.1f} s "
                    "of the twin with the robot still"
                )
        if cfg.sleep_objects:
            set_sleep(model, self._object_trees, start_asleep=True)
        self._rest_objects_here(data)
        self.mppi.reset()
        controls, states, step_ms, step_cpu_ms, step_paths = [], [], [], [], []
        paths, iteration_start = cfg.mppi.num_paths, 0.0
        path_budget = (
            PathBudget(
                cfg.mppi.num_paths, min(cfg.min_paths, cfg.mppi.num_paths), cfg.realtime_factor, cfg.mppi.control_dt_s
            )
            if cfg.realtime_factor > 0
            else None
        )
        met_streak, met, error, held = 0, False, float("inf"), False
        message = "step budget used"
        budget = reward.step_budget
        for step in range(budget):
            if should_stop is not None and should_stop():
                message = "stopped"
                break
            t0, c0 = time.perf_counter(), time.process_time()
            if path_budget is not None and step > 0:  # the whole previous iteration, not just its MPPI step
                paths = path_budget.update(paths, t0 - iteration_start)
            iteration_start = t0
            state = get_state(model, data)
            gripper = reward.gripper_command(robot.spec.gripper_open, robot.spec.gripper_closed)
            fixed = {int(robot.gripper_actuator): gripper}
            jac = self.tcp_jacobian(data)
            cap_m_s = reward.hand_speed_cap_m_s()
            speed_cap = linear_speed_cap(jac[:3], robot.arm_actuators, cap_m_s) if cap_m_s > 0 else None
            result = self.mppi.step(
                state, ctrl, reward, self.noise_basis(data, jac), fixed, num_paths=paths, rate_filter=speed_cap
            )
            step_ms.append(1e3 * (time.perf_counter() - t0))
            step_cpu_ms.append(1e3 * (time.process_time() - c0))
            step_paths.append(paths)
            self._last_ret, self._last_w = result.returns, result.weights
            for target in self.mppi.rollout.substep_controls(ctrl, result.control[None, None])[0]:
                data.ctrl[:] = target
                mujoco.mj_step(model, data)
            ctrl = result.control
            if not np.all(np.isfinite(data.qpos)):
                message = f"twin physics diverged at step {step}"
                met, error = False, float("inf")
                break
            if observe is not None and observe(step, ctrl, model, data):
                self._rest_objects_here(data)
            elif cfg.sleep_objects:
                self._sleeping_poses_as_rest(data)
            executed = get_state(model, data)
            states.append(reward.update(executed))
            controls.append(ctrl.copy())
            if stream is not None:
                stream(ctrl[robot.actuators])
            self.mppi.shift()
            met, error = self.evaluate(reward, executed, request.tolerance_m)
            close = reward.error(executed) <= cfg.done_goal_distance_m
            met_streak = met_streak + 1 if (met and reward.holds_goal() and close) else 0
            if feedback is not None:
                feedback(step + 1, budget, states[-1], error)
            if cfg.done_hold_steps and met_streak >= cfg.done_hold_steps:
                message = f"task met in the twin after {step + 1} steps"
                held = True
                break
        else:
            message = "task met in the twin" if met else "step budget used without meeting the task"
        controls_arr = np.array(controls).reshape(-1, model.nu)
        times = cfg.mppi.control_dt_s * np.arange(1, len(controls_arr) + 1)
        replays = ReplayOutcome(0, 0)
        if met and observe is None and stream is None and request.resume_state is None:
            replays = replay_in_perturbed_twins(
                model, initial_state, initial_ctrl, controls_arr, self.mppi.rollout.substeps,
                int(round(cfg.settle_s / model.opt.timestep)), robot.qpos_adr, robot.arm_actuators,
                lambda end: self.evaluate(reward, end, request.tolerance_m)[0], cfg.replay,
            )  # fmt: skip
            message += f"; met in {replays.met} of {replays.twins} perturbed twins" if replays.twins else ""
        return PlanResult(
            success=bool(met),
            message=message,
            final_error_m=float(error),
            times_s=times,
            controls=controls_arr,
            joint_names=robot.spec.trajectory_joint_names,
            joint_positions=controls_arr[:, robot.actuators],
            states=states,
            step_ms=np.array(step_ms),
            step_cpu_ms=np.array(step_cpu_ms),
            step_paths=np.array(step_paths, dtype=int),
            held=held,
            replays=replays,
        )
