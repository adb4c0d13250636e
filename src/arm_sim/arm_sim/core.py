"""The sim node's pure core: a seeded scene, its simulated world, a camera and trajectory tracking."""

import time

import mujoco
import numpy as np

from arm_core.camera import look_at
from arm_sim import robot
from arm_sim.appearance import DEFAULT_DOMAIN
from arm_sim.depth_noise import DepthNoise
from arm_sim.objects import object_pool
from arm_sim.scenes import cluttered_scene
from arm_sim.world import SERVO_PERIOD_S, SimWorld, servo_targets

COMMAND_NAMES = tuple(robot.JOINT_NAMES) + (robot.FINGER_JOINT_NAMES[0],)


class SimSession:
    """A seeded cluttered scene with the robot, stepped in simulated time and rendered on demand."""

    def __init__(
        self,
        seed=0,
        objects=None,
        split="heldout",
        n_objects=None,
        camera_eye=(0.7, 0.0, 0.5),
        camera_target=(0.0, 0.0, 0.05),
        width=640,
        height=480,
        fovy_deg=45.0,
        depth_noise=True,
        visual_domain=DEFAULT_DOMAIN,
    ):
        self.rng = np.random.default_rng(seed)
        pool = object_pool(objects, split=split, seed=seed)
        self.scene = cluttered_scene(pool, self.rng, n_objects=n_objects, domain=visual_domain)
        self.world = SimWorld(self.scene, robot_arm=True, width=width, height=height, fovy_deg=fovy_deg)
        self.world.settle(0.5)
        self.T_world_camera = look_at(camera_eye, camera_target)
        self.noise = DepthNoise(enabled=bool(depth_noise))
        self.time_s = 0.0
        self._targets = np.zeros((0, len(COMMAND_NAMES)))  # servo targets still to take, one per SERVO_PERIOD_S
        self._next_servo_s = 0.0

    def command(self) -> np.ndarray:
        """The current servo targets: 7 joint angles (rad) and the finger opening (m)."""
        return self.world.data.ctrl[:8].copy()

    def follow(self, joint_names, times_s, positions, start_s: float | None = None) -> int:
        """Replace the trajectory the servos follow (times from start_s, simulated s; None: from now;
        positions per joint in joint_names, interpolated from the current command at SERVO_PERIOD_S):
        the number of servo targets queued. Parts of one plan sent as it is planned share one time
        base, so a part that arrives a tick late continues the plan instead of repeating a tick. Raises
        ValueError (trajectory_targets) and keeps the old trajectory then."""
        started_s_ago = 0.0 if start_s is None else self.time_s - float(start_s)
        self._targets = trajectory_targets(
            joint_names, times_s, positions, self.command(), SERVO_PERIOD_S, started_s_ago=started_s_ago
        )
        self._next_servo_s = self.time_s
        return len(self._targets)

    def command_gripper(self, position: float) -> float:
        """Set the finger's servo target (m, clipped to its range) now and for the rest of the followed
        trajectory, which keeps driving the arm (the gripper has its own controller): the target set."""
        lo, hi = self.world.model.actuator_ctrlrange[len(COMMAND_NAMES) - 1]
        target = float(np.clip(position, lo, hi))
        self.world.data.ctrl[len(COMMAND_NAMES) - 1] = target
        if len(self._targets):
            self._targets[:, -1] = target
        return target

    def finger_effort_n(self) -> float:
        """The finger actuator's force, N (absolute)."""
        return float(abs(self.world.data.actuator_force[len(COMMAND_NAMES) - 1]))

    @property
    def following(self) -> bool:
        return len(self._targets) > 0

    def step(self, dt_s: float) -> None:
        """Advance dt_s of simulated time; every SERVO_PERIOD_S the servos take the followed trajectory's
        next target (after its end they hold the last one), as SimWorld.execute drives them."""
        model, data = self.world.model, self.world.data
        lo, hi = model.actuator_ctrlrange[:8].T
        end_s = self.time_s + dt_s
        while self.time_s < end_s - 1e-9:
            if len(self._targets) and self.time_s >= self._next_servo_s - 1e-9:
                data.ctrl[:8] = np.clip(self._targets[0], lo, hi)
                self._targets = self._targets[1:]
                self._next_servo_s += SERVO_PERIOD_S
            until_s = min(end_s, self._next_servo_s) if len(self._targets) else end_s
            substeps = max(1, int(round((until_s - self.time_s) / model.opt.timestep)))
            mujoco.mj_step(model, data, nstep=substeps)
            self.time_s += substeps * model.opt.timestep

    def render(self):
        start = time.perf_counter()
        frame = self.world.render(self.T_world_camera, noise=self.noise, rng=self.rng, stamp_s=self.time_s)
        return frame, 1e3 * (time.perf_counter() - start)

    def visible_fractions(self) -> np.ndarray:
        return self.world.render(self.T_world_camera, noise=DepthNoise(enabled=False)).visible_fraction

    def ground_truth_meshes(self):
        """[(world mesh, [world convex parts])] of every object at its current pose."""
        out = []
        for placed, T in zip(self.scene.objects, self.world.object_poses(), strict=True):
            mesh = placed.model.mesh.copy()
            mesh.apply_scale(placed.scale)
            mesh.apply_transform(T)
            parts = []
            for vertices, faces in placed.convex_parts_local():
                parts.append((vertices @ T[:3, :3].T + T[:3, 3], faces))
            out.append((mesh, parts))
        return out

    def close(self) -> None:
        self.world.close()


def trajectory_targets(
    joint_names,
    times_s,
    positions,
    current: np.ndarray,
    dt_s: float,
    max_duration_s: float = 120.0,
    started_s_ago: float = 0.0,
) -> np.ndarray:
    """A JointTrajectory's joints and points, validated, as servo targets every dt_s (world.servo_targets;
    started_s_ago: how long ago its header stamp was). Joints missing from joint_names keep their
    current target. Raises ValueError."""
    names = list(joint_names)
    unknown = [n for n in names if n not in COMMAND_NAMES]
    if unknown:
        raise ValueError(f"unknown joints {unknown}; expected a subset of {list(COMMAND_NAMES)}")
    times_s = np.asarray(times_s, dtype=np.float64)
    positions = np.asarray(positions, dtype=np.float64).reshape(len(times_s), len(names))
    if len(times_s) == 0:
        raise ValueError("trajectory has no points")
    if not (np.all(np.isfinite(times_s)) and np.all(np.isfinite(positions))):
        raise ValueError("trajectory has non-finite times or positions")
    if np.any(np.diff(times_s) <= 0) or times_s[0] < 0 or times_s[-1] > max_duration_s:
        raise ValueError("time_from_start must increase strictly, start >= 0 and end within the duration limit")
    columns = [COMMAND_NAMES.index(n) for n in names]
    full = np.tile(current, (len(times_s), 1))
    full[:, columns] = positions
    return servo_targets(times_s, full, current, dt_s, started_s_ago)
