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
        self._contact = p - n * PT_R  # pusher centre when touching (m)
        self._pre = p - n * (PT_R + PT_STANDOFF)  # pusher centre behind the contact (m)
        tau = p[:, 0] * n[:, 1] - p[:, 1] * n[:, 0]  # torque arm (m) of a unit push
        u = np.concatenate([n, (PT_YAW_LEN * PT_K * tau)[:, None]], axis=1)
        self._u = u / np.linalg.norm(u, axis=1, keepdims=True)  # predicted twist directions
        self._seg = np.linspace(0.0, 1.0, 9)[1:-1]  # interior sample fractions of a path segment

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

        if err < PT_GOAL_POS and abs(eyaw) < PT_GOAL_YAW:
            # At the goal: back away from the block at 0.1 m/s until the pusher's edge is 3 cm
            # clear, then stand still, so the block rests untouched through the success hold.
            if float(_pt.t_sdf(p)) > PT_R + 0.03:
                return np.zeros(2)
            return rot @ (0.1 * self._grad(p))

        # 1-2. Score every candidate push against the desired twist.
        want = np.array([e[0], e[1], PT_YAW_LEN * eyaw])
        want /= np.linalg.norm(want)
        align = self._u @ want
        pre_w = bw + self._pre @ rot.T
        reach = np.all(np.abs(pre_w) < _pt.WALL_INNER - PT_R - 0.005, axis=1)
        # Travel: distance to the segment from pre-contact point to contact (the push funnel),
        # so a pusher already pushing at a candidate pays nothing to keep pushing there.
        rel = p - self._contact
        along = np.clip(np.einsum("kj,kj->k", rel, self._n), -PT_STANDOFF, 0.0)
        travel = np.linalg.norm(rel - along[:, None] * self._n, axis=1)
        score = np.where(reach, align - PT_TRAVEL_COST * travel, -np.inf)
        k = int(np.argmax(score))
        n, t, c0, g = self._n[k], self._t[k], self._contact[k], self._pre[k]

        # 3a. Behind the contact and on its line (within 6 mm sideways, from 8 mm behind the
        # pre-contact point to 1 cm past the contact): push through it, steering back onto the
        # line at 5 (m/s)/m of sideways error.
        rel = p - c0
        along, lat = float(rel @ n), float(rel @ t)
        if abs(lat) < 0.006 and -(PT_STANDOFF + 0.008) < along < 0.01:
            twist_err = math.hypot(err, PT_YAW_LEN * eyaw)  # m
            speed = min(max(PT_PUSH_GAIN * twist_err, PT_V_PUSH[0]), PT_V_PUSH[1])
            v = speed * n - 5.0 * lat * t
            return rot @ v
        # 3b. Path to the pre-contact point clear of the T: go straight there.
        dg = g - p
        dist = float(np.linalg.norm(dg))
        speed = min(max(PT_MOVE_GAIN * dist, PT_V_MOVE[0]), PT_V_MOVE[1])
        path = p + self._seg[:, None] * dg
        # Clear = the path never comes closer to the T than the pusher is now (or than R + 2 mm).
        floor = min(PT_R + 0.002, float(_pt.t_sdf(p)) - 0.001)
        if np.all(_pt.t_sdf(path) > floor):
            return rot @ (speed * dg / max(dist, 1e-9))
        # 3c. Otherwise orbit the T at a safe clearance, the shorter way round.
        grad = self._grad(p)
        tang = np.array([-grad[1], grad[0]])  # counter-clockwise around the T
        a_p = math.atan2(*(p - PT_ORBIT_CENTER)[::-1])
        a_g = math.atan2(*(g - PT_ORBIT_CENTER)[::-1])
        if _pt.wrap_angle(a_g - a_p) < 0.0:
            tang = -tang
        gap = float(_pt.t_sdf(p)) - PT_R  # m between pusher edge and block
        radial = min(max(20.0 * (PT_CLEAR - gap), -1.0), 1.0)  # saturates at 5 cm off the orbit
        v = tang + radial * grad
        return rot @ (PT_V_MOVE[1] * v / max(np.linalg.norm(v), 1e-9))

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
