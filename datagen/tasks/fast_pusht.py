"""PushT's simulators for lockstep (datagen.lockstep): lanes that share one MjData, stepped as a batch.
The engine's fast copies of pusht_env.PushTEnv's stepping, kept off the file a learner reads.

    SharedPushTEnv(share=env)  = pusht_env.PushTEnv, bit for bit, in the MjData of `env`
    step_many(envs, actions)   = [env.step(a) for env, a in zip(envs, actions)]'s obs, success, done

both checked by tests/test_envs.py::test_pusht_step_many_on_a_shared_mjdata_is_step_bit_for_bit (six
envs sharing one MjData against six alone, poses read between steps; it fails with the parking below
removed or with mjSTATE_PHYSICS in place of mjSTATE_INTEGRATION) and, for copies and pickles,
tests/test_gym_envs.py::test_a_copy_of_a_pusht_env_that_shares_an_mjdata_is_a_standalone_env.

Why: making an MjData costs about 1 ms in MuJoCo's Python bindings, and 256 of them compete for the
cache; lanes that share one load their own state before they touch the simulator and save the state
of the env that used it last (_claim): mjSTATE_INTEGRATION, everything mj_step reads. A fast copy uses
the env's own private step parts (_advance, _fill), so the two cannot drift apart;
tests/test_package_layering.py allows this module, and only this one, pusht_env's private names.
"""

from __future__ import annotations

import mujoco
import numpy as np

from pusht_env import ACT_DIM, ACTION_LIMIT, MAX_STEPS, OBS_DIM, SIM_STATE, PushTEnv

__all__ = ["SharedPushTEnv", "step_many"]


class _Seat:
    """Which of the envs sharing an MjData has its state loaded in it now."""

    owner = None


class SharedPushTEnv(PushTEnv):
    """A PushTEnv that can share its compiled model and its MjData with other envs, each keeping its own
    state (SIM_STATE) while another uses the simulator. Read a shared env's state through its accessors:
    env.data holds whichever env's state was loaded last."""

    def __init__(self, share: SharedPushTEnv | None = None) -> None:
        if share is None:
            self._seat, self._state = _Seat(), None  # the first claim (set_start, below) takes the seat
            super().__init__()
        else:  # a model already checked, an MjData already made
            self._seat, self.model = share._seat, share.model
            self._state = np.zeros(mujoco.mj_stateSize(share.model, SIM_STATE))
            self._attach(share.data)
        if self._state is None:
            self._state = np.zeros(mujoco.mj_stateSize(self.model, SIM_STATE))  # this env's, while parked

    def _claim(self) -> bool:
        """Load this env's state into the MjData it shares if another env used it last (that env's
        state is saved first). True if it loaded: MjData's derived quantities are then stale until the
        next mj_step or mj_forward."""
        seat = self._seat
        if seat.owner is self:
            return False
        if seat.owner is not None:
            mujoco.mj_getState(self.model, self.data, seat.owner._state, SIM_STATE)
            mujoco.mj_setState(self.model, self.data, self._state, SIM_STATE)
        seat.owner = self
        return True

    # every way in to the simulator claims it first
    @property
    def pusher_pos(self) -> np.ndarray:
        self._claim()
        return super().pusher_pos

    @property
    def block_pose(self) -> np.ndarray:
        self._claim()
        return super().block_pose

    def set_start(self, *start) -> np.ndarray:
        self._claim()
        return super().set_start(*start)

    def _advance(self, vx: float, vy: float) -> tuple[float, float]:
        self._claim()
        return PushTEnv._advance(self, vx, vy)

    def render(self, size: int = 96) -> np.ndarray:
        if self._claim():
            mujoco.mj_forward(self.model, self.data)
        return super().render(size)

    def __getstate__(self) -> dict:
        """As PushTEnv's, from this env's own state: a copy is a standalone env that shares nothing."""
        self._claim()
        return super().__getstate__()

    @staticmethod
    def step_many(envs, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return step_many(envs, actions)


def step_many(envs, actions) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """envs[i].step(actions[i]) for every i, bit for bit, without a reward or info per env: (obs
    (N, OBS_DIM) float32, success (N,) bool, done (N,) bool). One finiteness check and one clip for the
    batch, then only the control writes, the physics and the counters per env (PushTEnv._advance, the
    rules' one home) and the observation (PushTEnv._fill)."""
    n = len(envs)
    a = np.asarray(actions, dtype=np.float64).reshape(n, ACT_DIM)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"non-finite action in {a}")
    a = np.clip(a, -ACTION_LIMIT, ACTION_LIMIT).tolist()  # step's min(max()) for finite values
    obs = np.empty((n, OBS_DIM), np.float32)
    success, done = np.empty(n, bool), np.empty(n, bool)
    for i, env in enumerate(envs):
        env._advance(*a[i])
        env._fill(obs[i])
        success[i] = env._success
        done[i] = env._success or env._steps >= MAX_STEPS
    return obs, success, done
