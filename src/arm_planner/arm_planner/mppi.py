"""Model predictive path integral control (Williams et al. 2015) over batched MuJoCo rollouts.

Controls are absolute actuator targets (position actuators: joint targets). Each step samples
`num_paths` control sequences of `horizon` control steps around a warm-started nominal sequence,
rolls all of them out in one call of `mujoco.rollout.Rollout` (persistent C thread pool, no Python
loop per physics step), scores them with a task reward and moves the nominal sequence to the
reward-weighted average. Noise is temporally smoothed (AR(1) along the horizon); every sampled
sequence is clipped to the actuator ranges and to a per-step rate limit before rollout, so the
weighted average (a convex combination) respects the same limits.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import mujoco
import mujoco.rollout
import numpy as np

STATE_SPEC = mujoco.mjtState.mjSTATE_FULLPHYSICS


@dataclass
class MppiConfig:
    """Defaults are the paper's (appendix "MPPI Parameters") except where noted."""

    steps: int = 200
    num_paths: int = 25
    horizon: int = 5
    control_dt_s: float = 0.02
    # Twin physics step; None keeps the model's. Must divide control_dt_s.
    physics_dt_s: float | None = 0.01
    # Temperature relative to the spread of path returns in the current batch.
    temperature: float = 0.1
    # AR(1) coefficient of the noise along the horizon (0 = white noise).
    noise_smoothing: float = 0.6
    # Low-pass on the executed controls: new = a * planned + (1 - a) * previous.
    action_filter: float = 1.0
    nthread: int = 2
    seed: int = 0


def state_layout(model: mujoco.MjModel) -> tuple[int, int]:
    """Offsets of qpos and qvel inside a STATE_SPEC state vector."""
    t = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_TIME)
    return t, t + model.nq


def get_state(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    state = np.empty(mujoco.mj_stateSize(model, STATE_SPEC))
    mujoco.mj_getState(model, data, state, STATE_SPEC)
    return state


class BatchedRollout:
    """Rolls out [N, H] control-step sequences; returns the state at the end of each control step."""

    def __init__(self, model: mujoco.MjModel, control_dt_s: float, nthread: int = 2):
        self.model = model
        substeps = control_dt_s / model.opt.timestep
        if abs(substeps - round(substeps)) > 1e-6 or round(substeps) < 1:
            raise ValueError(
                f"control step {control_dt_s} s is not a multiple of timestep {model.opt.timestep}"
            )
        self.substeps = int(round(substeps))
        self.nthread = max(0, int(nthread))
        self._runner = mujoco.rollout.Rollout(nthread=self.nthread)
        self._datas = [mujoco.MjData(model) for _ in range(max(1, self.nthread))]
        self.nstate = mujoco.mj_stateSize(model, STATE_SPEC)
        self._buffers: dict[tuple[int, int], np.ndarray] = {}
        self._models: dict[int, list[mujoco.MjModel]] = {}

    def __call__(self, initial_state: np.ndarray, controls: np.ndarray) -> np.ndarray:
        """initial_state [nstate], controls [N, H, nu] -> states [N, H, nstate]."""
        n, h, nu = controls.shape
        nstep = h * self.substeps
        ctrl = np.ascontiguousarray(np.repeat(controls, self.substeps, axis=1), dtype=np.float64)
        out = self._buffers.get((n, nstep))
        if out is None:
            out = np.empty((n, nstep, self.nstate))
            self._buffers[(n, nstep)] = out
        init = np.ascontiguousarray(np.broadcast_to(initial_state, (n, self.nstate)), dtype=np.float64)
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

    def close(self) -> None:
        self._runner.close()


@dataclass
class ControlLimits:
    """Box limits per actuator and the largest change of a target per control step."""

    low: np.ndarray
    high: np.ndarray
    max_delta: np.ndarray

    @staticmethod
    def from_model(model: mujoco.MjModel, max_rate: np.ndarray | float, control_dt_s: float) -> ControlLimits:
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
        max_delta = np.broadcast_to(np.asarray(max_rate, dtype=np.float64) * control_dt_s, (model.nu,)).copy()
        return ControlLimits(low, high, max_delta)

    def apply(self, previous: np.ndarray, sequences: np.ndarray) -> np.ndarray:
        """Clip sequences [..., H, nu] that start after control `previous` [nu] to rate and box limits."""
        deltas = np.diff(
            np.concatenate(
                [np.broadcast_to(previous, sequences.shape[:-2] + (1,) + previous.shape), sequences], axis=-2
            ),
            axis=-2,
        )
        deltas = np.clip(deltas, -self.max_delta, self.max_delta)
        out = np.empty_like(sequences)
        current = np.broadcast_to(previous, sequences.shape[:-2] + previous.shape).copy()
        for t in range(sequences.shape[-2]):
            current = np.clip(current + deltas[..., t, :], self.low, self.high)
            out[..., t, :] = current
        return out


RewardFn = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""(states [N, H, nstate], controls [N, H, nu]) -> rewards [N, H]."""


@dataclass
class StepResult:
    control: np.ndarray
    returns: np.ndarray
    weights: np.ndarray


class Mppi:
    """Warm-started MPPI over a fixed model; the reward and the noise shape may change every step."""

    def __init__(self, model: mujoco.MjModel, config: MppiConfig, limits: ControlLimits):
        self.model = model
        self.config = config
        self.limits = limits
        self.rollout = BatchedRollout(model, config.control_dt_s, config.nthread)
        self.rng = np.random.default_rng(config.seed)
        self.nominal = np.zeros((config.horizon, model.nu))

    def reset(self, control: np.ndarray) -> None:
        """Nominal sequence = hold `control` [nu] over the horizon."""
        self.nominal = np.tile(np.asarray(control, dtype=np.float64), (self.config.horizon, 1))

    def sample_noise(self, noise_basis: np.ndarray) -> np.ndarray:
        """Smoothed noise [N, H, nu] = AR(1) white noise [N, H, k] through basis [k, nu]; path 0 is zero."""
        cfg = self.config
        k = noise_basis.shape[0]
        white = self.rng.standard_normal((cfg.num_paths, cfg.horizon, k))
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
    ) -> StepResult:
        """One MPPI iteration from `state`; returns the first control of the updated nominal sequence.

        `noise_basis` [k, nu]: rows are the directions (with scale) noise is drawn along.
        `fixed_controls`: actuator index -> value forced over the whole horizon (e.g. the gripper).
        """
        cfg = self.config
        candidates = self.nominal[None] + self.sample_noise(noise_basis)
        if fixed_controls:
            for a, value in fixed_controls.items():
                candidates[..., a] = value
        candidates = self.limits.apply(previous_control, candidates)
        states = self.rollout(state, candidates)
        rewards = reward_fn(states, candidates)
        returns = np.nan_to_num(rewards.sum(axis=1), nan=-1e9, neginf=-1e9)
        spread = max(float(returns.max() - returns.min()), 1e-9)
        weights = np.exp((returns - returns.max()) / (cfg.temperature * spread))
        weights /= weights.sum()
        self.nominal = np.einsum("n,nhu->hu", weights, candidates)
        control = cfg.action_filter * self.nominal[0] + (1.0 - cfg.action_filter) * previous_control
        return StepResult(control=control, returns=returns, weights=weights)

    def shift(self) -> None:
        """Warm start: drop the executed first control, repeat the last one."""
        self.nominal = np.concatenate([self.nominal[1:], self.nominal[-1:]], axis=0)

    def close(self) -> None:
        self.rollout.close()
