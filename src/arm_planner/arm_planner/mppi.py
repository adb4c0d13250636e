"""Model predictive path integral control (Williams et al. 2015) over batched MuJoCo rollouts.

Controls are absolute actuator targets (position actuators: joint targets). Each step samples
`num_paths` control sequences of `horizon` control steps around a warm-started nominal sequence,
rolls them out with `mujoco.rollout` (C loops over the physics steps, threads over the paths; see
BatchedRollout), scores them with a task reward and moves the nominal sequence to the
reward-weighted average. Noise is temporally smoothed (AR(1) along the horizon); every sampled
sequence is clipped to the actuator ranges and to a per-step rate limit before rollout, so the
weighted average (a convex combination) respects the same limits.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import mujoco
import mujoco.rollout
import numpy as np

from arm_core.settings import setting

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS


@dataclass
class MppiConfig:
    """Defaults are the paper's (appendix "MPPI Parameters") except where noted."""

    steps: int = setting(200, "MPPI steps per plan (paper: 200)", 1, 5000, parameter=True)
    num_paths: int = setting(25, "Sampled paths per step (paper: 25)", 2, 1000, parameter=True)
    horizon: int = setting(5, "Control steps per path (paper: 5)", 1, 100)
    control_dt_s: float = setting(0.02, "Control step, s (paper: 0.02)", 0.002, 0.2)
    temperature: float = setting(0.05, "MPPI temperature relative to the spread of path returns", 1e-4, 10.0)
    noise_smoothing: float = setting(0.8, "AR(1) coefficient of the sampling noise along the horizon", 0.0, 0.99)
    nthread: int = setting(2, "Rollout threads (0: the calling thread)", 0, 64, parameter=True)
    seed: int = setting(0, "Sampling noise seed", 0, 2**31 - 1)


def state_layout(model: mujoco.MjModel) -> tuple[int, int]:
    """Offsets of qpos and qvel inside a STATE_SPEC state vector."""
    t = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_TIME)
    return t, t + model.nq


def get_state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    return state


def free_body_trees(model: mujoco.MjModel) -> np.ndarray:
    """Kinematic trees rooted at a free joint (the objects)."""
    roots = [
        b
        for b in range(1, model.nbody)
        if model.body_parentid[b] == 0
        and model.body_jntnum[b] > 0
        and model.jnt_type[model.body_jntadr[b]] == mujoco.mjtJoint.mjJNT_FREE
    ]
    return np.unique(model.body_treeid[roots]).astype(int)


def set_sleep(model: mujoco.MjModel, trees: np.ndarray, start_asleep: bool) -> None:
    """Enable MuJoCo sleeping; `trees` may sleep when at rest, and start asleep after a reset if asked.

    A sleeping tree costs no collision or constraint work; contact with an awake tree, or a state
    with nonzero velocity for it, wakes it.
    """
    model.opt.enableflags |= int(mujoco.mjtEnableBit.mjENBL_SLEEP)
    policy = mujoco.mjtSleepPolicy.mjSLEEP_INIT if start_asleep else mujoco.mjtSleepPolicy.mjSLEEP_ALLOWED
    model.tree_sleep_policy[np.asarray(trees, dtype=int)] = int(policy)


class PathBudget:
    """Paths per MPPI step that keep planning within `realtime_factor` of the motion it plans (MJPC
    style: under CPU load a plan gets fewer rollouts, not more time). After each step the cost of a
    path is estimated from the step's wall time (exponential average); the next step gets as many
    paths as fit realtime_factor * control_dt_s, within [min_paths, max_paths]."""

    def __init__(
        self, max_paths: int, min_paths: int, realtime_factor: float, control_dt_s: float, smoothing: float = 0.3
    ):
        if not 1 <= min_paths <= max_paths or realtime_factor <= 0 or control_dt_s <= 0 or not 0 < smoothing <= 1:
            raise ValueError(
                f"need 1 <= min_paths {min_paths} <= max_paths {max_paths}, realtime_factor {realtime_factor} > 0, "
                f"control_dt_s {control_dt_s} > 0 and smoothing {smoothing} in (0, 1]"
            )
        self.max_paths, self.min_paths = int(max_paths), int(min_paths)
        self.step_budget_s = float(realtime_factor) * float(control_dt_s)
        self.smoothing = float(smoothing)
        self.path_cost_s: float | None = None
        self.paths = self.max_paths

    def update(self, paths_used: int, step_wall_s: float) -> int:
        """Record a step's wall time with paths_used paths -> paths for the next step."""
        cost = max(float(step_wall_s), 0.0) / max(int(paths_used), 1)
        self.path_cost_s = (
            cost if self.path_cost_s is None else (1 - self.smoothing) * self.path_cost_s + self.smoothing * cost
        )
        fit = int(self.step_budget_s / max(self.path_cost_s, 1e-9))
        self.paths = int(np.clip(fit, self.min_paths, self.max_paths))
        return self.paths


def ramp_controls(previous: np.ndarray, controls: np.ndarray, substeps: int) -> np.ndarray:
    """Targets per physics step [N, H * substeps, nu] of control steps [N, H, nu] after `previous` [nu]:
    linear from the previous control step's target to this one's (what a trajectory controller
    interpolating the waypoints applies)."""
    n, h, nu = controls.shape
    start = np.concatenate([np.broadcast_to(previous, (n, 1, nu)), controls[:, :-1]], axis=1)
    frac = (np.arange(1, substeps + 1) / substeps)[None, None, :, None]
    ramp = start[:, :, None] + (controls - start)[:, :, None] * frac
    return np.ascontiguousarray(ramp.reshape(n, h * substeps, nu))


class BatchedRollout:
    """Rolls out [N, H] control-step sequences; returns the state at the end of each control step.

    With sleep enabled on the model, each path starts from freshly reset data, so trees with the
    INIT policy start asleep (at qpos0) unless the initial state gives them a velocity, whatever ran
    before on that data. Path p runs on data p % threads. (One batched call over per-thread data,
    paths assigned to threads as the pool schedules them, gave different closed-loop outcomes from
    run to run with 2 threads; the rollout sets the physics state, not the rest of the data.)
    """

    def __init__(self, model: mujoco.MjModel, control_dt_s: float, nthread: int = 2):
        self.model = model
        substeps = control_dt_s / model.opt.timestep
        if abs(substeps - round(substeps)) > 1e-6 or round(substeps) < 1:
            raise ValueError(f"control step {control_dt_s} s is not a multiple of timestep {model.opt.timestep}")
        self.substeps = int(round(substeps))
        self.nthread = max(0, int(nthread))
        self._runner = mujoco.rollout.Rollout(nthread=self.nthread)
        self._datas = [mujoco.MjData(model) for _ in range(max(1, self.nthread))]
        self.nstate = mujoco.mj_stateSize(model, STATE_SPEC)
        self._buffers: dict[tuple[int, int], np.ndarray] = {}
        self._models: dict[int, list[mujoco.MjModel]] = {}
        self._workers = ThreadPoolExecutor(len(self._datas)) if len(self._datas) > 1 else None
        self._path_runners = [mujoco.rollout.Rollout(nthread=0) for _ in self._datas]
        self._one_model = [model]
        for data in self._datas:
            mujoco.mj_resetData(model, data)

    def substep_controls(self, previous: np.ndarray, controls: np.ndarray) -> np.ndarray:
        """Targets per physics step [N, H * substeps, nu] (ramp_controls)."""
        return ramp_controls(previous, controls, self.substeps)

    def __call__(self, initial_state: np.ndarray, controls: np.ndarray, previous: np.ndarray) -> np.ndarray:
        """initial_state [nstate], controls [N, H, nu] after control `previous` [nu] -> states [N, H, nstate]."""
        n, h, nu = controls.shape
        nstep = h * self.substeps
        ctrl = self.substep_controls(previous, controls)
        out = self._buffers.get((n, nstep))
        if out is None:
            out = np.empty((n, nstep, self.nstate))
            self._buffers[(n, nstep)] = out
        init = np.ascontiguousarray(np.broadcast_to(initial_state, (n, self.nstate)), dtype=np.float64)
        if self.model.opt.enableflags & int(mujoco.mjtEnableBit.mjENBL_SLEEP):
            self._rollout_paths_apart(init, ctrl, nstep, out)
            return out[:, self.substeps - 1 :: self.substeps]
        models = self._models.get(n)
        if models is None:
            models = self._models[n] = [self.model] * n
        self._runner.rollout(
            models,
            self._datas,
            init,
            ctrl,
            control_spec=mujoco.mjtState.mjSTATE_CTRL,
            skip_checks=True,
            nstep=nstep,
            state=out,
        )
        return out[:, self.substeps - 1 :: self.substeps]

    def _rollout_paths_apart(self, init: np.ndarray, ctrl: np.ndarray, nstep: int, out: np.ndarray) -> None:
        """Each path on freshly reset data; path p on data p % threads (GIL released in the rollout)."""

        def run(worker: int) -> None:
            data, runner = self._datas[worker], self._path_runners[worker]
            for p in range(worker, len(init), len(self._datas)):
                mujoco.mj_resetData(self.model, data)
                runner.rollout(
                    self._one_model,
                    [data],
                    init[p : p + 1],
                    ctrl[p : p + 1],
                    control_spec=mujoco.mjtState.mjSTATE_CTRL,
                    skip_checks=True,
                    nstep=nstep,
                    state=out[p : p + 1],
                )

        if self._workers is None:
            run(0)
        else:
            list(self._workers.map(run, range(len(self._datas))))

    def close(self) -> None:
        self._runner.close()
        for runner in self._path_runners:
            runner.close()
        if self._workers is not None:
            self._workers.shutdown()


@dataclass
class ControlLimits:
    """Box limits per actuator and the largest rate of change of a target (ctrl units per second)."""

    low: np.ndarray
    high: np.ndarray
    max_rate: np.ndarray

    @staticmethod
    def from_model(model: mujoco.MjModel, max_rate: np.ndarray | float) -> ControlLimits:
        low = np.full(model.nu, -np.inf)
        high = np.full(model.nu, np.inf)
        limited = model.actuator_ctrllimited.astype(bool)
        low[limited] = model.actuator_ctrlrange[limited, 0]
        high[limited] = model.actuator_ctrlrange[limited, 1]
        for a in range(model.nu):
            if model.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_JOINT:
                j = model.actuator_trnid[a, 0]
                if model.jnt_limited[j] and model.actuator_gear[a, 0] == 1.0:
                    low[a] = max(low[a], model.jnt_range[j, 0])
                    high[a] = min(high[a], model.jnt_range[j, 1])
        rate = np.broadcast_to(np.asarray(max_rate, dtype=np.float64), (model.nu,)).copy()
        return ControlLimits(low, high, rate)

    def integrate(self, previous: np.ndarray, rates: np.ndarray, dt: float) -> np.ndarray:
        """Targets [..., H, nu] reached from `previous` [nu] by rates [..., H, nu], within both limits."""
        steps = np.clip(rates, -self.max_rate, self.max_rate) * dt
        out = np.empty_like(steps)
        current = np.broadcast_to(previous, steps.shape[:-2] + previous.shape)
        for t in range(steps.shape[-2]):
            current = np.clip(current + steps[..., t, :], self.low, self.high)
            out[..., t, :] = current
        return out


RewardFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(states [N, H, nstate], controls [N, H, nu]) -> rewards [N, H]."""
RateFilter = Callable[[np.ndarray], np.ndarray]
"""Sampled rates [N, H, nu] -> rates within a task's constraint (must keep convex combinations within it)."""


def linear_speed_cap(jac_linear: np.ndarray, actuators: np.ndarray, max_speed_m_s: float) -> RateFilter:
    """Rates scaled down, per path and step, so the point with linear Jacobian `jac_linear` [3, len(actuators)]
    (w.r.t. the rates of `actuators`) moves at most max_speed_m_s. A ball is convex, so the weighted
    average of capped rates is capped too."""
    actuators = np.asarray(actuators, dtype=int)

    def cap(rates: np.ndarray) -> np.ndarray:
        speed = np.linalg.norm(rates[..., actuators] @ jac_linear.T, axis=-1)
        scale = np.minimum(1.0, max_speed_m_s / np.maximum(speed, 1e-12))
        out = rates.copy()
        out[..., actuators] *= scale[..., None]
        return out

    return cap


@dataclass
class StepResult:
    control: np.ndarray
    returns: np.ndarray
    weights: np.ndarray


class Mppi:
    """Warm-started MPPI over a fixed model; the reward and the noise shape may change every step.

    The decision variables are the rates of the actuator targets over the horizon (a position servo's
    target moves at most `max_rate`); the targets are their running integral from the last executed
    control. The nominal rate sequence carries over between steps (shifted), so consistent motion
    is kept instead of being re-discovered by the noise every step.
    """

    def __init__(self, model: mujoco.MjModel, config: MppiConfig, limits: ControlLimits):
        self.model = model
        self.config = config
        self.limits = limits
        self.rollout = BatchedRollout(model, config.control_dt_s, config.nthread)
        self.rng = np.random.default_rng(config.seed)
        self.nominal = np.zeros((config.horizon, model.nu))

    def reset(self) -> None:
        """Nominal sequence = hold still."""
        self.nominal = np.zeros((self.config.horizon, self.model.nu))

    def sample_noise(self, noise_basis: np.ndarray, num_paths: int | None = None) -> np.ndarray:
        """Smoothed noise [N, H, nu] = AR(1) white noise [N, H, k] through basis [k, nu]; path 0 is zero.
        N = num_paths (default config.num_paths)."""
        cfg = self.config
        k = noise_basis.shape[0]
        white = self.rng.standard_normal((int(num_paths or cfg.num_paths), cfg.horizon, k))
        beta = cfg.noise_smoothing
        smooth = np.empty_like(white)
        smooth[:, 0] = white[:, 0]
        gain = np.sqrt(1.0 - beta * beta)
        for t in range(1, cfg.horizon):
            smooth[:, t] = beta * smooth[:, t - 1] + gain * white[:, t]
        smooth[0] = 0.0
        return smooth @ noise_basis

    def step(
        self,
        state: np.ndarray,
        previous_control: np.ndarray,
        reward_fn: RewardFn,
        noise_basis: np.ndarray,
        fixed_controls: dict[int, float] | None = None,
        num_paths: int | None = None,
        rate_filter: RateFilter | None = None,
    ) -> StepResult:
        """One MPPI iteration from `state`; returns the next control (targets) to execute.

        `noise_basis` [k, nu]: rows are rate directions (with scale, ctrl units / s) noise is drawn along.
        `fixed_controls`: actuator index -> target forced over the whole horizon (e.g. the gripper).
        `num_paths`: paths sampled this step (default config.num_paths).
        `rate_filter`: a constraint applied to every sampled rate sequence (e.g. linear_speed_cap).
        """
        cfg = self.config
        rates = np.clip(
            self.nominal[None] + self.sample_noise(noise_basis, num_paths), -self.limits.max_rate, self.limits.max_rate
        )
        previous = np.asarray(previous_control, dtype=np.float64)
        fixed = fixed_controls or {}
        for a in fixed:
            rates[..., a] = 0.0
        if rate_filter is not None:
            rates = rate_filter(rates)
        controls = self.limits.integrate(previous, rates, cfg.control_dt_s)
        for a, value in fixed.items():
            controls[..., a] = value
        states = self.rollout(state, controls, previous)
        rewards = reward_fn(states, controls)
        returns = rewards.sum(axis=1)
        finite = np.isfinite(returns)
        if not finite.any():
            raise FloatingPointError("every rollout returned a non-finite reward")
        best = returns[finite].max()
        spread = max(float(best - np.median(returns[finite])), 1e-9)
        weights = np.where(finite, np.exp((np.where(finite, returns, best) - best) / (cfg.temperature * spread)), 0.0)
        weights /= weights.sum()
        self.nominal = np.einsum("n,nhu->hu", weights, rates)
        control = self.limits.integrate(previous, self.nominal[None, :1], cfg.control_dt_s)[0, 0]
        for a, value in fixed.items():
            control[a] = value
        return StepResult(control=control, returns=returns, weights=weights)

    def shift(self) -> None:
        """Warm start: drop the executed first rate, repeat the last one."""
        self.nominal = np.concatenate([self.nominal[1:], self.nominal[-1:]], axis=0)

    def close(self) -> None:
        self.rollout.close()
