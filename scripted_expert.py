"""Scripted experts for the two chapter embodiments (PushT and the ALOHA cube handoff).

Each expert is a policy object with ``reset()`` and ``act(obs) -> float32 action``. Optional
Gaussian action noise is drawn from a generator seeded by the caller, so a noisy demo is
bit-for-bit reproducible for a given seed.
"""

from __future__ import annotations

import math
import operator

import numpy as np

# --- PushT expert ---
# A Markov pushing policy: the action is a function of the current 10-D observation alone (no
# phase, no memory beyond the noise generator), so a behaviour-cloning MLP on the state can
# imitate it. Every step it re-plans from scratch:
#   1. Desired block motion, in the block frame: the position error (m) and the yaw error (rad)
#      stacked as (ex, ey, YAW_LEN * eyaw). Far from the target the position error dominates, so
#      the block is mostly translated; near it the yaw error dominates, so it is mostly rotated.
#   2. Candidate pushes: points on the T's faces and corners with an inward push direction n.
#      Under quasi-static pushing a unit push along n at point p moves the block with twist
#      proportional to (n_x, n_y, K * (p x n)), K = linear / rotational damping of the block.
#      The candidate whose predicted twist best aligns with the desired one wins, minus a cost
#      for how far the pusher must travel to get behind it (this also keeps the choice steady).
#   3. If the pusher sits behind the chosen contact, push through it (8 (m/s) per m of remaining
#      error, within 0.1..0.8 m/s: fast far from the goal, slowing as the block settles).
#      Otherwise move to a pre-contact point behind it: straight when the path is clear of the
#      T, else orbit the T at a safe clearance.
#   4. Inside a tight goal zone (well within the success tolerances) back off from the block
#      and let it rest, so the 5-step success hold is met.
import pusht_env as _pt

_PT_R = _pt.PUSHER_RADIUS  # m
_PT_K = _pt.BLOCK_SLIDE_DAMPING / _pt.BLOCK_YAW_DAMPING  # 1/m^2: (N s/m) / (N m s/rad)
_PT_YAW_LEN = 0.12  # m per rad: how a yaw error weighs against a position error
_PT_STANDOFF = 0.012  # m: gap between pusher edge and block at the pre-contact point
_PT_CLEAR = 0.022  # m: edge clearance kept while orbiting the block
_PT_TRAVEL_COST = 2.0  # score per m of pusher travel to reach a candidate
_PT_V_PUSH = (0.10, 0.80)  # m/s, min and max pushing speed (fast far out, slows near the goal)
_PT_PUSH_GAIN = 8.0  # 1/s: pushing speed per unit of remaining (scaled) twist error (m)
_PT_V_MOVE = (0.10, 0.80)  # m/s, min and max repositioning (and orbiting) speed
_PT_MOVE_GAIN = 10.0  # 1/s: repositioning speed per m of distance to the pre-contact point
_PT_GOAL_POS = 0.010  # m: inside this and _PT_GOAL_YAW the expert backs off
_PT_GOAL_YAW = 0.06  # rad
_PT_ORBIT_CENTER = np.array([0.0, -0.03])  # m, block frame: a point near the T's middle


def _pt_candidates() -> tuple[np.ndarray, np.ndarray]:
    """Contact points p (K, 2) and inward unit push directions n (K, 2), block frame (m)."""
    bx, by = _pt.BAR_HALF
    sx = _pt.STEM_HALF[0]
    sy0 = _pt.STEM_CENTER_Y - _pt.STEM_HALF[1]  # stem bottom y (-0.105)
    r = _PT_R
    pts, nrm = [], []

    def face(points, n):
        for p in points:
            pts.append(p)
            nrm.append(n)

    face([(x, by) for x in np.linspace(-bx + 0.01, bx - 0.01, 11)], (0.0, -1.0))  # bar top
    for sgn in (-1.0, 1.0):
        face([(sgn * bx, y) for y in (-0.008, 0.0, 0.008)], (-sgn, 0.0))  # bar ends
        face(
            [(sgn * x, -by) for x in np.linspace(sx + r + 0.004, bx - 0.006, 3)], (0.0, 1.0)
        )  # bar underside
        face([(sgn * sx, y) for y in np.linspace(-by - r - 0.004, sy0 + 0.006, 5)], (-sgn, 0.0))  # stem sides
    face([(x, sy0) for x in (-0.01, 0.0, 0.01)], (0.0, 1.0))  # stem bottom
    # Convex corners: a round pusher on a corner can push along any direction in the corner's cone.
    corners = [((sgn * bx, by), (sgn, 0.0), (0.0, 1.0)) for sgn in (-1.0, 1.0)]
    corners += [((sgn * bx, -by), (sgn, 0.0), (0.0, -1.0)) for sgn in (-1.0, 1.0)]
    corners += [((sgn * sx, sy0), (sgn, 0.0), (0.0, -1.0)) for sgn in (-1.0, 1.0)]
    for p, a, b in corners:
        for w in (0.25, 0.5, 0.75):
            out = (1 - w) * np.array(a) + w * np.array(b)
            out /= np.linalg.norm(out)
            pts.append(p)
            nrm.append(tuple(-out))
    return np.array(pts, dtype=np.float64), np.array(nrm, dtype=np.float64)


def _mv(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rows of m (N, a, b) @ v (N, b) -> (N, a): one BLAS gemv per row, as `m[i] @ v[i]` is."""
    return np.matmul(m, v[:, :, None])[:, :, 0]


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rows' dot products (N, d) . (N, d) -> (N,): one BLAS dot per row, as `a[i] @ b[i]` is."""
    return np.matmul(a[:, None, :], b[:, :, None])[:, 0, 0]


def _norm(v: np.ndarray) -> np.ndarray:
    """np.linalg.norm of each row (N, d) -> (N,): sqrt of its dot with itself, as numpy computes it."""
    return np.sqrt(_dot(v, v))


class PushTExpert:
    """Scripted PushT expert: ``act(obs) -> float32[2]`` pusher velocity (m/s), Markov in obs.

    ``noise`` is the std (m/s) of Gaussian noise added to every action, drawn from
    ``np.random.default_rng(seed)`` created once here; the sum is clipped to [-1, 1].
    """

    def __init__(self, noise: float = 0.0, seed: int = 0) -> None:
        self.noise = float(noise)
        self.seed = int(seed)
        self._rng = np.random.default_rng(self.seed)
        p, n = _pt_candidates()
        self._p, self._n = p, n
        self._t = np.stack([-n[:, 1], n[:, 0]], axis=1)  # tangent to each push direction
        self._contact = p - n * _PT_R  # pusher centre when touching (m)
        self._pre = p - n * (_PT_R + _PT_STANDOFF)  # pusher centre behind the contact (m)
        tau = p[:, 0] * n[:, 1] - p[:, 1] * n[:, 0]  # torque arm (m) of a unit push
        u = np.concatenate([n, (_PT_YAW_LEN * _PT_K * tau)[:, None]], axis=1)
        self._u = u / np.linalg.norm(u, axis=1, keepdims=True)  # predicted twist directions
        self._seg = np.linspace(0.0, 1.0, 9)[1:-1]  # interior sample fractions of a path segment
        # For _clean_batch: each candidate's n, t, contact and pre-contact point in one row; n and
        # the contact x and y apart (2, 1, K); the push test's open bounds on (along, lat) (m); the
        # observation columns of the target and the pusher; _grad's stencil offsets, x and y apart,
        # after a zero one, signed so that adding them rounds as _grad's p + (h, 0.0), p - (h, 0.0),
        # ... do (x + -0.0 == x and x - 0.0 == x + -0.0, the sign of a zero included); the signs of
        # the counter-clockwise tangent (-g1, g0).
        self._cand = np.concatenate([n, self._t, self._contact, self._pre], axis=1)  # (K, 8)
        self._n_xy = np.ascontiguousarray(n.T)[:, None, :]
        self._contact_xy = np.ascontiguousarray(self._contact.T)[:, None, :]
        self._push_lo = np.array([-(_PT_STANDOFF + 0.008), -0.006])
        self._push_hi = np.array([0.01, 0.006])
        self._ep_cols = np.array([6, 7, 0, 1])
        h = 1e-5
        stencil = np.array([(-0.0, -0.0), (h, 0.0), (-h, -0.0), (0.0, h), (-0.0, -h)])
        self._stencil_xy = np.ascontiguousarray(stencil.T)[:, None, :]
        self._ccw = np.array([-1.0, 1.0])
        # The block's farthest |x| or |y| from every wall at which all pre-contact points are still
        # reachable: WALL_INNER - R - 5 mm less the farthest pre-contact point, less 1e-9 m for the
        # roundings of pre @ rot.T + bw (each well under 1e-15 m here).
        self._reach_free = _pt.WALL_INNER - _PT_R - 0.005 - float(np.hypot(*self._pre.T).max()) - 1e-9

    def reset(self) -> None:
        """Nothing to clear: the policy is memoryless (the noise generator keeps running)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        v = self._clean_action(np.asarray(obs, dtype=np.float64))
        if self.noise > 0.0:
            v = v + self._rng.normal(0.0, self.noise, size=2)
        return np.clip(v, -1.0, 1.0).astype(np.float32)

    def _clean_action(self, o: np.ndarray) -> np.ndarray:
        pw = o[0:2]
        bw = o[2:4]
        yaw = math.atan2(o[4], o[5])
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s], [s, c]])  # block frame -> world
        e = rot.T @ (o[6:8] - bw)  # position error in the block frame (m)
        eyaw = _pt.wrap_angle(math.atan2(o[8], o[9]) - yaw)  # rad
        p = rot.T @ (pw - bw)  # pusher in the block frame (m)
        err = math.hypot(e[0], e[1])

        if err < _PT_GOAL_POS and abs(eyaw) < _PT_GOAL_YAW:
            # At the goal: back away from the block at 0.1 m/s until the pusher's edge is 3 cm
            # clear, then stand still, so the block rests untouched through the success hold.
            if float(_pt.t_sdf(p)) > _PT_R + 0.03:
                return np.zeros(2)
            return rot @ (0.1 * self._grad(p))

        # 1-2. Score every candidate push against the desired twist.
        want = np.array([e[0], e[1], _PT_YAW_LEN * eyaw])
        want /= np.linalg.norm(want)
        align = self._u @ want
        pre_w = bw + self._pre @ rot.T
        reach = np.all(np.abs(pre_w) < _pt.WALL_INNER - _PT_R - 0.005, axis=1)
        # Travel: distance to the segment from pre-contact point to contact (the push funnel),
        # so a pusher already pushing at a candidate pays nothing to keep pushing there.
        rel = p - self._contact
        along = np.clip(np.einsum("kj,kj->k", rel, self._n), -_PT_STANDOFF, 0.0)
        travel = np.linalg.norm(rel - along[:, None] * self._n, axis=1)
        score = np.where(reach, align - _PT_TRAVEL_COST * travel, -np.inf)
        k = int(np.argmax(score))
        n, t, c0, g = self._n[k], self._t[k], self._contact[k], self._pre[k]

        # 3a. Behind the contact and on its line (within 6 mm sideways, from 8 mm behind the
        # pre-contact point to 1 cm past the contact): push through it, steering back onto the
        # line at 5 (m/s)/m of sideways error.
        rel = p - c0
        along, lat = float(rel @ n), float(rel @ t)
        if abs(lat) < 0.006 and -(_PT_STANDOFF + 0.008) < along < 0.01:
            twist_err = math.hypot(err, _PT_YAW_LEN * eyaw)  # m
            speed = min(max(_PT_PUSH_GAIN * twist_err, _PT_V_PUSH[0]), _PT_V_PUSH[1])
            v = speed * n - 5.0 * lat * t
            return rot @ v
        # 3b. Path to the pre-contact point clear of the T: go straight there.
        dg = g - p
        dist = float(np.linalg.norm(dg))
        speed = min(max(_PT_MOVE_GAIN * dist, _PT_V_MOVE[0]), _PT_V_MOVE[1])
        path = p + self._seg[:, None] * dg
        # Clear = the path never comes closer to the T than the pusher is now (or than R + 2 mm).
        floor = min(_PT_R + 0.002, float(_pt.t_sdf(p)) - 0.001)
        if np.all(_pt.t_sdf(path) > floor):
            return rot @ (speed * dg / max(dist, 1e-9))
        # 3c. Otherwise orbit the T at a safe clearance, the shorter way round.
        grad = self._grad(p)
        tang = np.array([-grad[1], grad[0]])  # counter-clockwise around the T
        a_p = math.atan2(*(p - _PT_ORBIT_CENTER)[::-1])
        a_g = math.atan2(*(g - _PT_ORBIT_CENTER)[::-1])
        if _pt.wrap_angle(a_g - a_p) < 0.0:
            tang = -tang
        gap = float(_pt.t_sdf(p)) - _PT_R  # m between pusher edge and block
        radial = min(max(20.0 * (_PT_CLEAR - gap), -1.0), 1.0)  # saturates at 5 cm off the orbit
        v = tang + radial * grad
        return rot @ (_PT_V_MOVE[1] * v / max(np.linalg.norm(v), 1e-9))

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """``act`` for N observations at once: obs (N, 10) -> float32 (N, 2), row i bit-identical to
        ``act(obs[i])`` (tests/test_lockstep.py). The expert is Markov, so no per-env state is kept;
        noise would need one generator per env, so only the noise-free expert (the engine's) batches."""
        if self.noise > 0.0:
            raise ValueError("act_batch is for the noise-free expert; a noisy one draws per env (act)")
        o = np.asarray(obs, dtype=np.float64).reshape(-1, _pt.OBS_DIM)
        v = self._clean_batch(o)
        # np.clip(v, -1.0, 1.0) as act's, without its wrapper's cost: the same values, NaN included.
        return np.minimum(np.maximum(v, -1.0, out=v), 1.0, out=v).astype(np.float32)

    def _clean_batch(self, o: np.ndarray) -> np.ndarray:
        """_clean_action over rows, every term computed as the scalar path computes it. The rules that
        keep the bits:
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
            where an error bound already settles the comparison (the reach test below).
        Apart from the transcendental calls and BLAS's per-env routines, every step is one numpy call
        over all envs, the goal ones too (their pushes are computed, then dropped): a call costs a few
        microseconds whatever its length, so picking out each branch's rows would cost more."""
        n = len(o)
        if n == 0:
            return np.zeros((0, 2))
        # The per-env angles, with Python's math (rule 1).
        bx, by, sin_b, cos_b, _, _, sin_t, cos_t = o[:, 2:10].T.tolist()
        yaw = list(map(math.atan2, sin_b, cos_b))
        c, s = list(map(math.cos, yaw)), list(map(math.sin, yaw))
        eyaw = np.array(list(map(operator.sub, map(math.atan2, sin_t, cos_t), yaw)))
        eyaw = (eyaw + math.pi) % (2.0 * math.pi) - math.pi  # wrap_angle (rule 3)
        rot = np.empty((n, 2, 2))  # C-ordered per env, as the scalar np.array([[c, -s], [s, c]]) is
        rot[:, 0, 0] = rot[:, 1, 1] = c
        rot[:, 1, 0] = s
        np.negative(rot[:, 1, 0], out=rot[:, 0, 1])
        rot_t = rot.transpose(0, 2, 1)  # each env's rot.T: the same transposed view the scalar gemv gets
        # e = rot.T @ (target - block) and p = rot.T @ (pusher - block): one gemv per vector.
        ep = np.matmul(rot_t[:, None], (o[:, self._ep_cols].reshape(n, 2, 2) - o[:, None, 2:4])[..., None])
        e, p = ep[:, 0, :, 0], ep[:, 1, :, 0]  # (N, 2) each, block frame (m)
        err = np.array(list(map(math.hypot, *e.T.tolist())))
        yaw_err = _PT_YAW_LEN * eyaw  # m
        twist_err = np.array(list(map(math.hypot, err.tolist(), yaw_err.tolist())))
        goal = (err < _PT_GOAL_POS) & (np.abs(eyaw) < _PT_GOAL_YAW)
        any_goal = np.count_nonzero(goal) > 0

        # 1-2. Score every candidate push against the desired twist.
        want = np.concatenate([e, yaw_err[:, None]], axis=1)
        want /= np.maximum(_norm(want), 1e-300)[:, None]  # the max only keeps a goal env's 0/0 away
        align = np.matmul(self._u, want[:, :, None])[:, :, 0]  # (N, K): gemv per row, as self._u @ want
        rel = p.T[:, :, None] - self._contact_xy  # (2, N, K): x and y of p - contact
        rn = rel * self._n_xy
        along = np.maximum(rn[0] + rn[1], -_PT_STANDOFF)  # the einsum, then np.clip (rule 3)
        np.minimum(along, 0.0, out=along)
        rel -= along * self._n_xy
        rel *= rel
        travel = np.sqrt(rel[0] + rel[1])  # np.linalg.norm(..., axis=1) (rule 3)
        score = align - _PT_TRAVEL_COST * travel
        # Reach: pre_w = bw + pre @ rot.T (a gemm per env) within the walls. |pre_w| <= |bw| + |pre|
        # up to a few roundings, so while every block is far enough from the walls every candidate is
        # reachable whatever the gemm's last bits (rule 4); else compute it as the scalar path does.
        if max(max(bx), -min(bx), max(by), -min(by)) >= self._reach_free:
            pre_w = o[:, None, 2:4] + np.matmul(self._pre, rot_t)  # (N, K, 2): gemm per env
            bound = np.abs(pre_w) < _pt.WALL_INNER - _PT_R - 0.005
            score = np.where(bound[:, :, 0] & bound[:, :, 1], score, -np.inf)
        cand = self._cand[score.argmax(axis=1)]  # the chosen candidate's n, t, contact, pre (N, 8)
        nt, g = cand[:, 0:4].reshape(n, 2, 2), cand[:, 6:8]

        # 3a. Behind the contact and on its line: push through it.
        rel = p - cand[:, 4:6]
        along_lat = np.matmul(nt[:, :, None, :], rel[:, None, :, None])[:, :, 0, 0]  # rel @ n, rel @ t: dots
        push = (self._push_lo < along_lat) & (along_lat < self._push_hi)  # |lat| < 6 mm, along in range
        push = push[:, 0] & push[:, 1]
        speed = np.minimum(np.maximum(_PT_PUSH_GAIN * twist_err, _PT_V_PUSH[0]), _PT_V_PUSH[1])
        v_push = speed[:, None] * nt[:, 0] - (5.0 * along_lat[:, 1:2]) * nt[:, 1]
        # 3b. Path to the pre-contact point clear of the T: go straight there.
        dg = g - p
        dist = np.sqrt(_dot(dg, dg))  # np.linalg.norm of a vector: sqrt of its dot with itself
        speed = np.minimum(np.maximum(_PT_MOVE_GAIN * dist, _PT_V_MOVE[0]), _PT_V_MOVE[1])
        v_straight = speed[:, None] * dg / np.maximum(dist, 1e-9)[:, None]
        # One distance-field call for every env's points, x and y apart (2, N, 12): p, _grad's
        # stencil around p, then the path (p + f dg as f dg + p: IEEE addition commutes).
        pts = np.empty((2, n, 5 + len(self._seg)))
        np.add(p.T[:, :, None], self._stencil_xy, out=pts[:, :, :5])
        np.multiply(dg.T[:, :, None], self._seg, out=pts[:, :, 5:])
        pts[:, :, 5:] += p.T[:, :, None]
        sdf = _pt.t_sdf_xy(pts[0], pts[1])
        sdf_p = sdf[:, 0]
        floor = np.minimum(_PT_R + 0.002, sdf_p - 0.001)
        straight = np.minimum.reduce(sdf[:, 5:], axis=1) > floor  # np.all(t_sdf(path) > floor)
        # _grad from the stencil: p + (h, 0), p - (h, 0), p + (0, h), p - (0, h).
        grad = sdf[:, 1:5:2] - sdf[:, 2:5:2]
        nrm = _norm(grad)
        grad /= np.maximum(nrm, 1e-12)[:, None]  # the max only keeps 0/0 away: those rows are set next
        flat = nrm <= 1e-12
        if np.count_nonzero(flat):
            grad[flat] = (0.0, 1.0)
        # 3c. Otherwise orbit the T at a safe clearance, the shorter way round: counter-clockwise
        # unless the way to g is shorter clockwise (the atan2s only for the orbiting envs).
        tang = grad[:, ::-1] * self._ccw  # (-g1, g0)
        orbit = (~(push | straight | goal)).nonzero()[0]
        if orbit.size:
            (px, py), (gx, gy) = (
                (p[orbit] - _PT_ORBIT_CENTER).T.tolist(),
                (g[orbit] - _PT_ORBIT_CENTER).T.tolist(),
            )
            turn = np.array(list(map(math.atan2, gy, gx))) - np.array(list(map(math.atan2, py, px)))
            cw = orbit[(turn + math.pi) % (2.0 * math.pi) - math.pi < 0.0]  # wrap_angle (rule 3) < 0
            tang[cw] *= -1.0
        radial = np.minimum(np.maximum(20.0 * (_PT_CLEAR - (sdf_p - _PT_R)), -1.0), 1.0)
        v = tang + radial[:, None] * grad
        v_orbit = _PT_V_MOVE[1] * v / np.maximum(_norm(v), 1e-9)[:, None]
        move = np.where(push[:, None], v_push, np.where(straight[:, None], v_straight, v_orbit))
        # 4. At the goal: back away from the block, then stand still (zeros, not a rotated zero).
        if any_goal:
            move[goal] = 0.1 * grad[goal]
        out = _mv(rot, move)
        if any_goal:
            out[goal & (sdf_p > _PT_R + 0.03)] = 0.0
        return out

    @staticmethod
    def _grad(p: np.ndarray) -> np.ndarray:
        """Unit outward gradient of the T's distance field at block-frame point p."""
        h = 1e-5
        q = np.array([p + (h, 0.0), p - (h, 0.0), p + (0.0, h), p - (0.0, h)])
        d = _pt.t_sdf(q)
        g = np.array([d[0] - d[1], d[2] - d[3]])
        nrm = np.linalg.norm(g)
        return g / nrm if nrm > 1e-12 else np.array([0.0, 1.0])


# --- ALOHA expert ---
from aloha_env import ACT_DIM, GRASP_RADIUS, HANDOFF_HALF_WIDTH  # noqa: E402


class AlohaExpert:
    """Pick with the right arm, carry to the middle, hand over, release, carry to the target, hold.

    The phase is re-derived from every observation (no phase memory), so the expert recovers
    by itself when noise or a failed grasp puts it somewhere unexpected:

    * "right has it"  = right closedness > 0.9 and right gripper within HOLD_DIST of the cube;
      "left has it"   = the same for the left gripper.
    * left has it:  if the right gripper is still closed, both arms keep still and the right
      one opens (release after the handoff); otherwise the left arm carries the cube to the
      target and holds it there (gripper kept closed), while the right arm backs off to x = 0.15.
    * right has it (left not): the right arm carries the cube to the handoff point
      H = (HANDOFF_X, target y). The left arm waits at H with its gripper open, and once the
      cube is at H and the left gripper is on it, the left gripper closes.
    * nobody has it: the right arm goes to the cube and closes on it (the left arm waits at H).

    Motion is a proportional velocity law towards each goal, capped at MAX_SPEED m/s.
    Grip closing uses hysteresis (start closing within CLOSE_DIST, keep closing while
    closedness > 0.3 and within KEEP_DIST) so that small position noise does not make the
    gripper chatter. Optional Gaussian noise of std ``noise`` (from ``np.random.default_rng(seed)``
    built in ``__init__``) is added to all six action dimensions before clipping to [-1, 1];
    the generator is not re-seeded by ``reset()``, so successive episodes get fresh noise.
    """

    GAIN = 6.0  # 1/s, proportional gain of the velocity law
    MAX_SPEED = 0.12  # m/s, cap on each end-effector's commanded speed
    HANDOFF_X = 0.0  # m, x of the handoff point (middle of the overlap |x| < 0.05)
    HOLD_DIST = 0.035  # m, gripper-to-cube distance read as "holding" (grasp offsets <= 0.03)
    CLOSE_DIST = 0.015  # m, start closing when this close to the cube
    KEEP_DIST = 0.028  # m, keep closing (once closedness > 0.3) while within this distance
    RIGHT_BACKOFF_X = 0.15  # m, where the right arm retreats after the handoff
    READY_DIST = 0.02  # m, cube-to-handoff-point distance at which the left gripper closes in

    def __init__(self, noise: float = 0.0, seed: int = 0) -> None:
        assert self.HOLD_DIST > GRASP_RADIUS and abs(self.HANDOFF_X) < HANDOFF_HALF_WIDTH
        self.noise = float(noise)
        self.seed = int(seed)
        self._rng = np.random.default_rng(seed)

    def reset(self) -> None:
        """Stateless policy: nothing to reset (the noise generator keeps running)."""

    def _vel(self, pos: np.ndarray, goal: np.ndarray) -> np.ndarray:
        v = self.GAIN * (goal - pos)
        speed = float(np.hypot(v[0], v[1]))
        if speed > self.MAX_SPEED:
            v *= self.MAX_SPEED / speed
        return v

    def _grip_cmd(self, dist: float, closedness: float) -> float:
        if dist < self.CLOSE_DIST or (closedness > 0.3 and dist < self.KEEP_DIST):
            return 1.0
        return -1.0

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """``act`` for N observations at once: obs (N, 10) -> float32 (N, 6), row i bit-identical to
        ``act(obs[i])`` (tests/test_lockstep.py). The phase is re-derived from each row (no per-env
        state); only the noise-free expert batches (a noisy one draws from one generator, in env order).
        Every term is elementwise: np.hypot is the same ufunc the scalar path calls on two scalars."""
        if self.noise > 0.0:
            raise ValueError("act_batch is for the noise-free expert; a noisy one draws per env (act)")
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
        """_vel over rows (N, 2): v scaled by MAX_SPEED / speed where the speed exceeds the cap."""
        v = self.GAIN * (goal - pos)
        speed = np.hypot(v[:, 0], v[:, 1])
        over = speed > self.MAX_SPEED
        with np.errstate(divide="ignore"):
            v[over] *= (self.MAX_SPEED / speed[over])[:, None]
        return v

    def _grip_batch(self, dist: np.ndarray, closedness: np.ndarray) -> np.ndarray:
        """_grip_cmd over rows: 1.0 (close) or -1.0 (open)."""
        close = (dist < self.CLOSE_DIST) | ((closedness > 0.3) & (dist < self.KEEP_DIST))
        return np.where(close, 1.0, -1.0)

    def act(self, obs) -> np.ndarray:
        o = np.asarray(obs, dtype=np.float64)
        r, rg, lft, lg, c, t = o[0:2], o[2], o[3:5], o[5], o[6:8], o[8:10]
        dr = float(np.hypot(*(r - c)))
        dl = float(np.hypot(*(lft - c)))
        right_has = rg > 0.9 and dr < self.HOLD_DIST
        left_has = lg > 0.9 and dl < self.HOLD_DIST
        handoff = np.array([self.HANDOFF_X, t[1]])

        if left_has:
            if rg > 0.05:  # release after the handoff: keep still, open right
                rv, rcmd = np.zeros(2), -1.0
                lv, lcmd = np.zeros(2), 1.0
            else:  # deliver: left carries the cube to the target
                rv, rcmd = self._vel(r, np.array([self.RIGHT_BACKOFF_X, r[1]])), -1.0
                lv, lcmd = self._vel(c, t), 1.0
        elif right_has:  # carry to the handoff point, left meets it there
            rv, rcmd = self._vel(c, handoff), 1.0
            if float(np.hypot(*(c - handoff))) < self.READY_DIST:
                lv, lcmd = self._vel(lft, c), self._grip_cmd(dl, lg)
            else:
                lv, lcmd = self._vel(lft, handoff), -1.0
        else:  # pick: right goes to the cube and closes on it
            rv, rcmd = self._vel(r, c), self._grip_cmd(dr, rg)
            lv, lcmd = self._vel(lft, handoff), -1.0

        action = np.array([rv[0], rv[1], rcmd, lv[0], lv[1], lcmd], dtype=np.float64)
        if self.noise > 0.0:
            action = action + self._rng.normal(0.0, self.noise, size=ACT_DIM)
        return np.clip(action, -1.0, 1.0).astype(np.float32)
