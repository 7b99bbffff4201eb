"""The scripted experts over a batch, for lockstep (datagen.lockstep): the engine's fast copies of
scripted_expert.py's act, kept off the file a learner reads.

    PushTBatch().act_batch(obs)   = PushTExpert(noise=0.0).act per row, bit for bit
    AlohaBatch().act_batch(obs)   = AlohaExpert(noise=0.0).act per row, bit for bit
    t_sdf_xy(x, y)                = pusht_env.t_sdf of the points (x, y), bit for bit

each checked by tests/test_lockstep.py (test_pusht_batched_expert_is_bit_identical,
test_aloha_batched_expert_is_bit_identical: thousands of real and noisy states). A fast copy reads the
very constants of the expert it copies (scripted_expert's _PT_ tuning and its precomputed candidates),
so the two cannot drift apart by a number; tests/test_package_layering.py allows this module, and only
this one, those private names. Only the noise-free expert batches: a noisy one draws from one generator
in env order (act).
"""

from __future__ import annotations

import math
import operator

import numpy as np

import pusht_env as _pt
from scripted_expert import (
    PT_CLEAR,
    PT_GOAL_POS,
    PT_GOAL_YAW,
    PT_MOVE_GAIN,
    PT_ORBIT_CENTER,
    PT_PUSH_GAIN,
    PT_R,
    PT_STANDOFF,
    PT_TRAVEL_COST,
    PT_V_MOVE,
    PT_V_PUSH,
    PT_YAW_LEN,
    AlohaExpert,
    PushTExpert,
)

__all__ = ["AlohaBatch", "PushTBatch", "t_sdf_xy"]

# The T's two boxes along a leading axis (2, 1, 1), bar first as t_sdf loops: centre y, half x, half y.
_BOXES = np.array([(0.0, *_pt.BAR_HALF), (_pt.STEM_CENTER_Y, *_pt.STEM_HALF)])
_T_CY, _T_HX, _T_HY = _BOXES.T[:, :, None, None]


def t_sdf_xy(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """pusht_env.t_sdf of the points (x, y), for x and y (A, B) of one shape -> (A, B): the bar and the
    stem broadcast along a leading axis, so every point goes through t_sdf's elementwise operations in
    the same order (the same bits) in 12 numpy calls instead of 23, for callers that evaluate many
    small point sets."""
    ex = np.abs(x) - _T_HX  # (2, A, B): bar, stem
    ey = np.abs(y - _T_CY) - _T_HY
    d = np.hypot(np.maximum(ex, 0.0), np.maximum(ey, 0.0)) + np.minimum(np.maximum(ex, ey), 0.0)
    return np.minimum(d[0], d[1])


def _mv(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rows of m (N, a, b) @ v (N, b) -> (N, a): one BLAS gemv per row, as `m[i] @ v[i]` is."""
    return np.matmul(m, v[:, :, None])[:, :, 0]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rows' dot products (N, d) . (N, d) -> (N,): one BLAS dot per row, as `a[i] @ b[i]` is."""
    return np.matmul(a[:, None, :], b[:, :, None])[:, 0, 0]


def _norm(v: np.ndarray) -> np.ndarray:
    """np.linalg.norm of each row (N, d) -> (N,): sqrt of its dot with itself, as numpy computes it."""
    return np.sqrt(_dot(v, v))


def _noise_free(expert) -> None:
    if expert.noise > 0.0:
        raise ValueError("a batch is for the noise-free expert; a noisy one draws per env (act)")


class PushTBatch:
    """PushTExpert's act over rows (act_batch), from the expert's own candidates. The expert is Markov,
    so no per-env state is kept."""

    def __init__(self, expert: PushTExpert | None = None) -> None:
        x = PushTExpert() if expert is None else expert
        _noise_free(x)
        self._n, self._t, self._contact, self._pre, self._u, self._seg = (
            x._n,
            x._t,
            x._contact,
            x._pre,
            x._u,
            x._seg,
        )
        # Each candidate's n, t, contact and pre-contact point in one row; n and
        # the contact x and y apart (2, 1, K); the push test's open bounds on (along, lat) (m); the
        # observation columns of the target and the pusher; _grad's stencil offsets, x and y apart,
        # after a zero one, signed so that adding them rounds as _grad's p + (h, 0.0), p - (h, 0.0),
        # ... do (x + -0.0 == x and x - 0.0 == x + -0.0, the sign of a zero included); the signs of
        # the counter-clockwise tangent (-g1, g0).
        self._cand = np.concatenate([self._n, self._t, self._contact, self._pre], axis=1)  # (K, 8)
        self._n_xy = np.ascontiguousarray(self._n.T)[:, None, :]
        self._contact_xy = np.ascontiguousarray(self._contact.T)[:, None, :]
        self._push_lo = np.array([-(PT_STANDOFF + 0.008), -0.006])
        self._push_hi = np.array([0.01, 0.006])
        self._ep_cols = np.array([6, 7, 0, 1])
        h = 1e-5
        stencil = np.array([(-0.0, -0.0), (h, 0.0), (-h, -0.0), (0.0, h), (-0.0, -h)])
        self._stencil_xy = np.ascontiguousarray(stencil.T)[:, None, :]
        self._ccw = np.array([-1.0, 1.0])
        # The block's farthest |x| or |y| from every wall at which all pre-contact points are still
        # reachable: WALL_INNER - R - 5 mm less the farthest pre-contact point, less 1e-9 m for the
        # roundings of pre @ rot.T + bw (each well under 1e-15 m here).
        self._reach_free = _pt.WALL_INNER - PT_R - 0.005 - float(np.hypot(*self._pre.T).max()) - 1e-9

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """PushTExpert.act for N observations at once: obs (N, 10) -> float32 (N, 2), row i bit for bit
        act(obs[i]) (tests/test_lockstep.py::test_pusht_batched_expert_is_bit_identical)."""
        o = np.asarray(obs, dtype=np.float64).reshape(-1, _pt.OBS_DIM)
        v = self._clean_batch(o)
        # np.clip(v, -1.0, 1.0) as act's, without its wrapper's cost: the same values, NaN included.
        return np.minimum(np.maximum(v, -1.0, out=v), 1.0, out=v).astype(np.float32)

    def _block_frame(self, o: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The expert's first lines over rows: rot (N, 2, 2), e and p (N, 2) in the block frame and eyaw
        (N,), equal to its yaw, rot, e = rot.T @ (target - bw), eyaw = wrap_angle(...) and
        p = rot.T @ (pw - bw); the angles with Python's math (rule 1), e and p one gemv each (rule 2)."""
        n = len(o)
        sin_b, cos_b, _, _, sin_t, cos_t = o[:, 4:10].T.tolist()
        yaw = list(map(math.atan2, sin_b, cos_b))
        c, s = list(map(math.cos, yaw)), list(map(math.sin, yaw))
        eyaw = np.array(list(map(operator.sub, map(math.atan2, sin_t, cos_t), yaw)))
        eyaw = (eyaw + math.pi) % (2.0 * math.pi) - math.pi  # wrap_angle (rule 3)
        rot = np.empty((n, 2, 2))  # C-ordered per env, as the scalar np.array([[c, -s], [s, c]]) is
        rot[:, 0, 0] = rot[:, 1, 1] = c
        rot[:, 1, 0] = s
        np.negative(rot[:, 1, 0], out=rot[:, 0, 1])
        rot_t = rot.transpose(0, 2, 1)  # each env's rot.T: the same transposed view the scalar gemv gets
        ep = np.matmul(rot_t[:, None], (o[:, self._ep_cols].reshape(n, 2, 2) - o[:, None, 2:4])[..., None])
        return rot, ep[:, 0, :, 0], ep[:, 1, :, 0], eyaw

    def _choose(self, o: np.ndarray, rot: np.ndarray, want: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The expert's steps 1-2 over rows: the chosen candidate's n, t, contact and pre (N, 8), equal to
        self._n[k], self._t[k], self._contact[k], self._pre[k] for k = argmax(score) (reach, align,
        travel); want is the desired twist [e, PT_YAW_LEN * eyaw], normalised here."""
        want /= np.maximum(_norm(want), 1e-300)[:, None]  # the max only keeps a goal env's 0/0 away
        align = np.matmul(self._u, want[:, :, None])[:, :, 0]  # (N, K): gemv per row, as self._u @ want
        rel = p.T[:, :, None] - self._contact_xy  # (2, N, K): x and y of p - contact
        rn = rel * self._n_xy
        along = np.maximum(rn[0] + rn[1], -PT_STANDOFF)  # the einsum, then np.clip (rule 3)
        np.minimum(along, 0.0, out=along)
        rel -= along * self._n_xy
        rel *= rel
        travel = np.sqrt(rel[0] + rel[1])  # np.linalg.norm(..., axis=1) (rule 3)
        score = align - PT_TRAVEL_COST * travel
        # Reach: pre_w = bw + pre @ rot.T (a gemm per env) within the walls. |pre_w| <= |bw| + |pre|
        # up to a few roundings, so while every block is far enough from the walls every candidate is
        # reachable whatever the gemm's last bits (rule 4); else compute it as the scalar path does.
        bx, by = o[:, 2:4].T.tolist()
        if max(max(bx), -min(bx), max(by), -min(by)) >= self._reach_free:
            pre_w = o[:, None, 2:4] + np.matmul(self._pre, rot.transpose(0, 2, 1))  # (N, K, 2): gemm per env
            bound = np.abs(pre_w) < _pt.WALL_INNER - PT_R - 0.005
            score = np.where(bound[:, :, 0] & bound[:, :, 1], score, -np.inf)
        return self._cand[score.argmax(axis=1)]

    def _push(self, p: np.ndarray, c0: np.ndarray, nt: np.ndarray, twist_err: np.ndarray):
        """The expert's step 3a over rows: (push, v_push), push (N,) equal to its test `abs(lat) < 0.006
        and -(PT_STANDOFF + 0.008) < along < 0.01` and v_push (N, 2) to its `speed * n - 5.0 * lat * t`
        (block frame), for nt the chosen (n, t) (N, 2, 2) and c0 the contact (N, 2)."""
        rel = p - c0
        along_lat = np.matmul(nt[:, :, None, :], rel[:, None, :, None])[:, :, 0, 0]  # rel @ n, rel @ t: dots
        push = (self._push_lo < along_lat) & (along_lat < self._push_hi)  # |lat| < 6 mm, along in range
        speed = np.minimum(np.maximum(PT_PUSH_GAIN * twist_err, PT_V_PUSH[0]), PT_V_PUSH[1])
        return push[:, 0] & push[:, 1], speed[:, None] * nt[:, 0] - (5.0 * along_lat[:, 1:2]) * nt[:, 1]

    @staticmethod
    def _straight(dg: np.ndarray) -> np.ndarray:
        """The expert's step 3b's velocity over rows (N, 2), equal to its `speed * dg / max(dist, 1e-9)`
        (block frame) for dg = g - p."""
        dist = np.sqrt(_dot(dg, dg))  # np.linalg.norm of a vector: sqrt of its dot with itself
        speed = np.minimum(np.maximum(PT_MOVE_GAIN * dist, PT_V_MOVE[0]), PT_V_MOVE[1])
        return speed[:, None] * dg / np.maximum(dist, 1e-9)[:, None]

    def _field(self, p: np.ndarray, dg: np.ndarray) -> np.ndarray:
        """Every t_sdf the expert takes, in one distance-field call (N, 5 + len(self._seg)): column 0
        equals t_sdf(p), columns 1-4 the four of _grad(p)'s stencil (after a copy of p), the rest
        t_sdf(path) for step 3b's path = p + self._seg[:, None] * dg (as f dg + p: IEEE addition
        commutes). The points x and y apart (2, N, 5 + len(self._seg))."""
        pts = np.empty((2, len(p), 5 + len(self._seg)))
        np.add(p.T[:, :, None], self._stencil_xy, out=pts[:, :, :5])
        np.multiply(dg.T[:, :, None], self._seg, out=pts[:, :, 5:])
        pts[:, :, 5:] += p.T[:, :, None]
        return t_sdf_xy(pts[0], pts[1])

    @staticmethod
    def _grad(sdf: np.ndarray) -> np.ndarray:
        """The expert's _grad(p) over rows (N, 2), from _field's stencil columns: p + (h, 0), p - (h, 0),
        p + (0, h), p - (0, h); (0, 1) where the gradient's norm is at most 1e-12."""
        grad = sdf[:, 1:5:2] - sdf[:, 2:5:2]
        nrm = _norm(grad)
        grad /= np.maximum(nrm, 1e-12)[:, None]  # the max only keeps 0/0 away: those rows are set next
        flat = nrm <= 1e-12
        if np.count_nonzero(flat):
            grad[flat] = (0.0, 1.0)
        return grad

    def _orbit(self, p: np.ndarray, g: np.ndarray, grad: np.ndarray, sdf_p: np.ndarray, orbit: np.ndarray):
        """The expert's step 3c over rows (N, 2), equal to its `PT_V_MOVE[1] * v / max(norm(v), 1e-9)`
        (block frame): around the T at a safe clearance, counter-clockwise unless the way to g is
        shorter clockwise; the atan2s only for the rows in orbit (indices), the ones that use it."""
        tang = grad[:, ::-1] * self._ccw  # (-g1, g0)
        if orbit.size:
            (px, py), (gx, gy) = (
                (p[orbit] - PT_ORBIT_CENTER).T.tolist(),
                (g[orbit] - PT_ORBIT_CENTER).T.tolist(),
            )
            turn = np.array(list(map(math.atan2, gy, gx))) - np.array(list(map(math.atan2, py, px)))
            cw = orbit[(turn + math.pi) % (2.0 * math.pi) - math.pi < 0.0]  # wrap_angle (rule 3) < 0
            tang[cw] *= -1.0
        radial = np.minimum(np.maximum(20.0 * (PT_CLEAR - (sdf_p - PT_R)), -1.0), 1.0)
        v = tang + radial[:, None] * grad
        return PT_V_MOVE[1] * v / np.maximum(_norm(v), 1e-9)[:, None]

    def _clean_batch(self, o: np.ndarray) -> np.ndarray:
        """PushTExpert._clean_action over rows, every term computed as the scalar path computes it. The
        rules that keep the bits:
        (1) transcendental terms (atan2, cos, sin, hypot) stay Python's math calls, one per env, since
            numpy's vector versions may round differently (and differ by CPU: SVML on AVX-512);
        (2) every product the scalar path hands to BLAS (``@``: gemv, gemm, and np.linalg.norm's dot)
            is a stacked np.matmul, which calls the same BLAS routine per env with the same shapes and
            layout, where an elementwise rewrite would not fuse multiply-adds the way OpenBLAS's
            kernels do (they differ in the last bit);
        (3) what the scalar path computes elementwise may be written as any elementwise arithmetic
            with the same roundings in the same order, numpy's or Python's floats (both IEEE, one
            rounding per operation): np.linalg.norm(x, axis=1) of (K, 2) rows is sqrt(x0*x0 + x1*x1)
            (a multiply, then add.reduce); the einsum "kj,kj->k" over a length-2 axis is a0*b0 + a1*b1
            (numpy's einsum kernels multiply and add separately, no FMA, in the x86-64 build; only a
            zero's sign may differ, which the squares after it erase); wrap_angle's % is numpy's
            remainder, which is Python's float % (an exact fmod, then one add); np.clip and Python's
            min(max(...)) are np.maximum then np.minimum (the same values, no NaN here);
        (4) a branch that the scalar path decides by a comparison may skip computing its operand
            where an error bound already settles the comparison (the reach test in _choose).
        Apart from the transcendental calls and BLAS's per-env routines, every step is one numpy call
        over all envs, the goal ones too (their pushes are computed, then dropped): a call costs a few
        microseconds whatever its length, so picking out each branch's rows would cost more."""
        if len(o) == 0:
            return np.zeros((0, 2))
        rot, e, p, eyaw = self._block_frame(o)
        err = np.array(list(map(math.hypot, *e.T.tolist())))
        yaw_err = PT_YAW_LEN * eyaw  # m
        twist_err = np.array(list(map(math.hypot, err.tolist(), yaw_err.tolist())))
        goal = (err < PT_GOAL_POS) & (np.abs(eyaw) < PT_GOAL_YAW)
        cand = self._choose(o, rot, np.concatenate([e, yaw_err[:, None]], axis=1), p)
        nt, g = cand[:, 0:4].reshape(len(o), 2, 2), cand[:, 6:8]
        push, v_push = self._push(p, cand[:, 4:6], nt, twist_err)  # 3a
        dg = g - p
        v_straight = self._straight(dg)  # 3b
        sdf = self._field(p, dg)
        sdf_p = sdf[:, 0]
        floor = np.minimum(PT_R + 0.002, sdf_p - 0.001)
        straight = np.minimum.reduce(sdf[:, 5:], axis=1) > floor  # np.all(t_sdf(path) > floor)
        grad = self._grad(sdf)
        v_orbit = self._orbit(p, g, grad, sdf_p, (~(push | straight | goal)).nonzero()[0])  # 3c
        move = np.where(push[:, None], v_push, np.where(straight[:, None], v_straight, v_orbit))
        # At the goal: back away from the block, then stand still (zeros, not a rotated zero).
        if any_goal := np.count_nonzero(goal) > 0:
            move[goal] = 0.1 * grad[goal]
        out = _mv(rot, move)
        if any_goal:
            out[goal & (sdf_p > PT_R + 0.03)] = 0.0
        return out


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
