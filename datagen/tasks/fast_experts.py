"""The ALOHA scripted expert over a batch, for lockstep (datagen.lockstep): the engine's fast copy of
scripted_expert.AlohaExpert's act, kept off the file a learner reads.

    AlohaBatch().act_batch(obs)   = AlohaExpert(noise=0.0).act per row, bit for bit

checked by tests/test_lockstep.py (test_aloha_batched_expert_is_bit_identical: thousands of real and noisy
states). It reads the very gains and distances of the expert it copies, so the two cannot drift apart by a
number. Only the noise-free expert batches: a noisy one draws from one generator in env order (act).
(The PushT expert needs no copy: scripted_expert.PushTExpert is written over a batch, its act a batch of
one.)
"""

from __future__ import annotations

import numpy as np

from scripted_expert import AlohaExpert

__all__ = ["AlohaBatch"]


def _noise_free(expert) -> None:
    if expert.noise > 0.0:
        raise ValueError("a batch is for the noise-free expert; a noisy one draws per env (act)")


class AlohaBatch:
    """AlohaExpert's act over rows (act_batch), with the expert's own gains and distances."""

    def __init__(self, expert: AlohaExpert | None = None) -> None:
        x = AlohaExpert() if expert is None else expert
        _noise_free(x)
        self.GAIN, self.MAX_SPEED, self.HANDOFF_X, self.HOLD_DIST = (
            x.GAIN,
            x.MAX_SPEED,
            x.HANDOFF_X,
            x.HOLD_DIST,
        )
        self.CLOSE_DIST, self.KEEP_DIST = x.CLOSE_DIST, x.KEEP_DIST
        self.RIGHT_BACKOFF_X, self.READY_DIST = x.RIGHT_BACKOFF_X, x.READY_DIST

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """AlohaExpert.act for N observations at once: obs (N, 10) -> float32 (N, 6), row i bit for bit
        act(obs[i]) (tests/test_lockstep.py::test_aloha_batched_expert_is_bit_identical). The phase is
        re-derived from each row (no per-env state). Every term is elementwise: np.hypot is the same
        ufunc the scalar path calls on two scalars."""
        o = np.asarray(obs, dtype=np.float64).reshape(-1, 10)
        r, rg, lft, lg, c, t = o[:, 0:2], o[:, 2], o[:, 3:5], o[:, 5], o[:, 6:8], o[:, 8:10]
        dr = np.hypot(*(r - c).T)
        dl = np.hypot(*(lft - c).T)
        right_has = (rg > 0.9) & (dr < self.HOLD_DIST)
        left_has = (lg > 0.9) & (dl < self.HOLD_DIST)
        handoff = np.stack([np.full(len(o), self.HANDOFF_X), t[:, 1]], axis=1)
        ready = np.hypot(*(c - handoff).T) < self.READY_DIST
        release = left_has & (rg > 0.05)
        deliver = left_has & ~release
        carry = ~left_has & right_has
        pick = ~left_has & ~right_has
        backoff = np.stack([np.full(len(o), self.RIGHT_BACKOFF_X), r[:, 1]], axis=1)

        # The right arm: goal and grip per phase (release: keep still, open).
        r_from = np.where(carry[:, None], c, r)
        r_goal = np.where(deliver[:, None], backoff, np.where(carry[:, None], handoff, c))
        rv = np.where(release[:, None], 0.0, self._vel_batch(r_from, r_goal))
        rcmd = np.where(carry, 1.0, np.where(pick, self._grip_batch(dr, rg), -1.0))
        # The left arm: carries the cube when delivering, meets it at the handoff point, else waits there.
        meet = carry & ready
        l_from = np.where(deliver[:, None], c, lft)
        l_goal = np.where(deliver[:, None], t, np.where(meet[:, None], c, handoff))
        lv = np.where(release[:, None], 0.0, self._vel_batch(l_from, l_goal))
        lcmd = np.where(left_has, 1.0, np.where(meet, self._grip_batch(dl, lg), -1.0))

        action = np.stack([rv[:, 0], rv[:, 1], rcmd, lv[:, 0], lv[:, 1], lcmd], axis=1)
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    def _vel_batch(self, pos: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """AlohaExpert._vel over rows (N, 2): v scaled by MAX_SPEED / speed where the speed exceeds the
        cap."""
        v = self.GAIN * (goal - pos)
        speed = np.hypot(v[:, 0], v[:, 1])
        over = speed > self.MAX_SPEED
        with np.errstate(divide="ignore"):
            v[over] *= (self.MAX_SPEED / speed[over])[:, None]
        return v

    def _grip_batch(self, dist: np.ndarray, closedness: np.ndarray) -> np.ndarray:
        """AlohaExpert._grip_cmd over rows: 1.0 (close) or -1.0 (open)."""
        close = (dist < self.CLOSE_DIST) | ((closedness > 0.3) & (dist < self.KEEP_DIST))
        return np.where(close, 1.0, -1.0)
