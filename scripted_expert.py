"""Scripted experts for the two chapter embodiments (PushT and the ALOHA cube handoff). (gym-pusht's, for
LeRobot's own PushT, lives beside its task: datagen/tasks/gym_pusht_expert.py.)

Each expert is a policy object with ``reset()`` and ``act(obs) -> float32 action``. Optional
Gaussian action noise is drawn from a generator seeded by the caller, so a noisy demo is
bit-for-bit reproducible for a given seed.
"""

from __future__ import annotations

import math

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

PT_R = _pt.PUSHER_RADIUS  # m
PT_K = _pt.BLOCK_SLIDE_DAMPING / _pt.BLOCK_YAW_DAMPING  # 1/m^2: (N s/m) / (N m s/rad)
PT_YAW_LEN = 0.12  # m per rad: how a yaw error weighs against a position error
PT_STANDOFF = 0.012  # m: gap between pusher edge and block at the pre-contact point
PT_CLEAR = 0.022  # m: edge clearance kept while orbiting the block
PT_TRAVEL_COST = 2.0  # score per m of pusher travel to reach a candidate
PT_V_PUSH = (0.10, 0.80)  # m/s, min and max pushing speed (fast far out, slows near the goal)
PT_PUSH_GAIN = 8.0  # 1/s: pushing speed per unit of remaining (scaled) twist error (m)
PT_V_MOVE = (0.10, 0.80)  # m/s, min and max repositioning (and orbiting) speed
PT_MOVE_GAIN = 10.0  # 1/s: repositioning speed per m of distance to the pre-contact point
PT_GOAL_POS = 0.010  # m: inside this and PT_GOAL_YAW the expert backs off
PT_GOAL_YAW = 0.06  # rad
PT_ORBIT_CENTER = np.array([0.0, -0.03])  # m, block frame: a point near the T's middle


def _pt_candidates() -> tuple[np.ndarray, np.ndarray]:
    """Contact points p (K, 2) and inward unit push directions n (K, 2), block frame (m)."""
    bx, by = _pt.BAR_HALF
    sx = _pt.STEM_HALF[0]
    sy0 = _pt.STEM_CENTER_Y - _pt.STEM_HALF[1]  # stem bottom y (-0.105)
    r = PT_R
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


def _rows_mv(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Each row's matrix times its vector, m (N, a, b) @ v (N, b) -> (N, a): a stack of `m[i] @ v[i]`."""
    return (m @ v[:, :, None])[:, :, 0]


def _rows_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Each row's dot product, (N, d) . (N, d) -> (N,): a stack of `a[i] @ b[i]`."""
    return (a[:, None, :] @ b[:, :, None])[:, 0, 0]


def _unit_gradient(d: np.ndarray) -> np.ndarray:
    """Unit gradient (N, 2) of a distance field from its values d (N, 4) at p + (h, 0), p - (h, 0),
    p + (0, h), p - (0, h) (central differences); (0, 1) where the field is flat."""
    g = d[:, 0::2] - d[:, 1::2]  # (N, 2)
    nrm = np.sqrt(_rows_dot(g, g))
    return np.where((nrm > 1e-12)[:, None], g / np.maximum(nrm, 1e-12)[:, None], (0.0, 1.0))


class PushTExpert:
    """Scripted PushT expert, Markov in the observation: ``act_batch(obs (N, 10)) -> float32 (N, 2)``
    pusher velocities (m/s), one row per env, so that the data engine decides for all its lockstep lanes
    in one call; ``act(obs (10,)) -> float32 (2,)`` is a batch of one.

    ``noise`` is the std (m/s) of Gaussian noise added to every action, drawn from
    ``np.random.default_rng(seed)`` created once here (a batch's rows in order); the sum is clipped to
    [-1, 1].

    A row's action has the same bits whatever shares its batch, on any x86-64 CPU: its angles (atan2,
    cos, sin, hypot) come from Python's math, row by row, since numpy's vector versions round
    differently from one CPU to another; each matrix product is a stack of the rows' own products
    (``rot.mT @ v``), which BLAS computes row by row as it would one alone; the rest is elementwise.
    """

    def __init__(self, noise: float = 0.0, seed: int = 0) -> None:
        self.noise = float(noise)
        self.seed = int(seed)
        self._rng = np.random.default_rng(self.seed)
        p, n = _pt_candidates()
        self._p, self._n = p, n  # (K, 2) each
        self._t = np.stack([-n[:, 1], n[:, 0]], axis=1)  # tangent to each push direction
        self._contact = p - n * PT_R  # pusher centre when touching (m)
        self._pre = p - n * (PT_R + PT_STANDOFF)  # pusher centre behind the contact (m)
        tau = p[:, 0] * n[:, 1] - p[:, 1] * n[:, 0]  # torque arm (m) of a unit push
        u = np.concatenate([n, (PT_YAW_LEN * PT_K * tau)[:, None]], axis=1)
        self._u = u / np.linalg.norm(u, axis=1, keepdims=True)  # predicted twist directions (K, 3)
        self._seg = np.linspace(0.0, 1.0, 9)[1:-1]  # interior sample fractions of a path segment
        # Central differences 1e-5 m apart: p + (h, 0), p - (h, 0), p + (0, h), p - (0, h), each
        # subtraction written as the addition of its negative (IEEE's x - y is x + -y, zeros' signs too).
        h = 1e-5
        self._stencil = np.array([(h, 0.0), (-h, -0.0), (0.0, h), (-0.0, -h)])

    def reset(self) -> None:
        """Nothing to clear: the policy is memoryless (the noise generator keeps running)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.act_batch(np.asarray(obs, dtype=np.float64)[None])[0]

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        v = self._clean_actions(np.asarray(obs, dtype=np.float64).reshape(-1, _pt.OBS_DIM))
        if self.noise > 0.0:
            v = v + self._rng.normal(0.0, self.noise, size=v.shape)
        return np.clip(v, -1.0, 1.0).astype(np.float32)

    def _clean_actions(self, o: np.ndarray) -> np.ndarray:
        """Steps 1-4 above for every row of o (N, 10) -> (N, 2) pusher velocities (m/s, world frame)."""
        n = len(o)
        yaw = list(map(math.atan2, o[:, 4].tolist(), o[:, 5].tolist()))  # block yaw (rad)
        c, s = np.array(list(map(math.cos, yaw))), np.array(list(map(math.sin, yaw)))
        rot = np.array([c, -s, s, c]).T.reshape(n, 2, 2)  # [[c, -s], [s, c]]: block frame -> world
        e = _rows_mv(rot.mT, o[:, 6:8] - o[:, 2:4])  # (N, 2) position error in the block frame (m)
        p = _rows_mv(rot.mT, o[:, 0:2] - o[:, 2:4])  # (N, 2) pusher in the block frame (m)
        target_yaw = list(map(math.atan2, o[:, 8].tolist(), o[:, 9].tolist()))  # rad
        eyaw = _pt.wrap_angle(np.array(target_yaw) - yaw)  # (N,) yaw error (rad)
        err = np.array(list(map(math.hypot, *e.T.tolist())))  # (N,) m
        twist_err = np.array(list(map(math.hypot, err.tolist(), (PT_YAW_LEN * eyaw).tolist())))  # (N,) m
        at_goal = (err < PT_GOAL_POS) & (np.abs(eyaw) < PT_GOAL_YAW)

        # 1-2. Score every candidate push (K) against the desired twist.
        want = np.concatenate([e, PT_YAW_LEN * eyaw[:, None]], axis=1)  # (N, 3)
        want /= np.maximum(np.sqrt(_rows_dot(want, want)), 1e-300)[:, None]  # the max: a goal row's 0/0
        align = (self._u @ want[:, :, None])[:, :, 0]  # (N, K)
        pre_w = o[:, None, 2:4] + self._pre @ rot.mT  # (N, K, 2) pre-contact points in the world (m)
        inside = np.abs(pre_w) < _pt.WALL_INNER - PT_R - 0.005
        reach = inside[:, :, 0] & inside[:, :, 1]  # (N, K)
        # Travel: distance to the segment from pre-contact point to contact (the push funnel),
        # so a pusher already pushing at a candidate pays nothing to keep pushing there.
        (cx, cy), (nx, ny) = self._contact.T, self._n.T  # (K,) each
        rx, ry = p[:, 0:1] - cx, p[:, 1:2] - cy  # (N, K) pusher - contact
        along = np.minimum(np.maximum(rx * nx + ry * ny, -PT_STANDOFF), 0.0)
        dx, dy = rx - along * nx, ry - along * ny
        travel = np.sqrt(dx * dx + dy * dy)  # (N, K) m
        score = np.where(reach, align - PT_TRAVEL_COST * travel, -np.inf)
        k = score.argmax(axis=1)  # (N,) each row's chosen candidate
        n_k, t_k, c0, g = self._n[k], self._t[k], self._contact[k], self._pre[k]  # (N, 2) each

        # 3a. Behind the contact and on its line (within 6 mm sideways, from 8 mm behind the
        # pre-contact point to 1 cm past the contact): push through it, steering back onto the
        # line at 5 (m/s)/m of sideways error.
        rel = p - c0
        along, lat = _rows_dot(rel, n_k), _rows_dot(rel, t_k)
        push = (np.abs(lat) < 0.006) & (-(PT_STANDOFF + 0.008) < along) & (along < 0.01)
        speed = np.minimum(np.maximum(PT_PUSH_GAIN * twist_err, PT_V_PUSH[0]), PT_V_PUSH[1])
        v_push = speed[:, None] * n_k - (5.0 * lat)[:, None] * t_k
        # 3b. Path to the pre-contact point clear of the T: go straight there.
        dg = g - p
        dist = np.sqrt(_rows_dot(dg, dg))
        speed = np.minimum(np.maximum(PT_MOVE_GAIN * dist, PT_V_MOVE[0]), PT_V_MOVE[1])
        v_straight = speed[:, None] * dg / np.maximum(dist, 1e-9)[:, None]
        # The T's distance field at every point this step reads, in one call: at the pusher (column 0),
        # around it for the field's gradient (1-4), along the straight path (5-11). (N, 12) m
        at = p[:, None, :]
        sdf = _pt.t_sdf(
            np.concatenate([at, at + self._stencil, at + self._seg[:, None] * dg[:, None, :]], axis=1)
        )
        sdf_p = sdf[:, 0]
        # Clear = the path never comes closer to the T than the pusher is now (or than R + 2 mm).
        floor = np.minimum(PT_R + 0.002, sdf_p - 0.001)
        straight = (sdf[:, 5:] > floor[:, None]).all(axis=1)
        # 3c. Otherwise orbit the T at a safe clearance, the shorter way round.
        grad = _unit_gradient(sdf[:, 1:5])
        tang = grad[:, ::-1] * (-1.0, 1.0)  # (-g_y, g_x): counter-clockwise around the T
        orbit = np.flatnonzero(~(at_goal | push | straight))  # the rows that orbit
        (px, py), (gx, gy) = (p[orbit] - PT_ORBIT_CENTER).T.tolist(), (g[orbit] - PT_ORBIT_CENTER).T.tolist()
        turn = np.array(list(map(math.atan2, gy, gx))) - np.array(list(map(math.atan2, py, px)))
        tang[orbit[_pt.wrap_angle(turn) < 0.0]] *= -1.0  # clockwise is the shorter way
        gap = sdf_p - PT_R  # m between pusher edge and block
        radial = np.minimum(np.maximum(20.0 * (PT_CLEAR - gap), -1.0), 1.0)  # saturates 5 cm off the orbit
        v = tang + radial[:, None] * grad
        v_orbit = PT_V_MOVE[1] * v / np.maximum(np.sqrt(_rows_dot(v, v)), 1e-9)[:, None]

        # 4. At the goal: back away from the block at 0.1 m/s until the pusher's edge is 3 cm clear,
        # then stand still, so the block rests untouched through the success hold.
        v = np.where(push[:, None], v_push, np.where(straight[:, None], v_straight, v_orbit))
        v = np.where(at_goal[:, None], 0.1 * grad, v)
        out = _rows_mv(rot, v)  # back to the world frame
        out[at_goal & (sdf_p > PT_R + 0.03)] = 0.0  # standing still: zeros, not a rotated zero (-0.0)
        return out


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
