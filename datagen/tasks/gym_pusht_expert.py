"""The scripted expert of gym-pusht (LeRobot's own PushT), beside its task module
(datagen/tasks/gym_pusht.py):
GymPushTExpert, and block_pose_from_keypoints / keypoint_residual, which read the block's pose back from
the 8 keypoints LeRobot's sets record. The chapter's own experts are in scripted_expert.py."""

from __future__ import annotations

import math

import numpy as np

__all__ = ["GymPushTExpert", "block_pose_from_keypoints", "keypoint_residual"]


def wrap_angle(a: float) -> float:
    """Wrap an angle (rad) to [-pi, pi): pusht_env.wrap_angle's arithmetic (this module imports no env)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


# gym-pusht (LeRobot's `pusht` extra) is the PushT of Diffusion Policy and LeRobot: a 2-D pymunk world in
# pixels, [0, 512]^2, with the same T as pusht_env (a 120 x 30 bar and a 30 x 90 stem: 1 px stands for
# 1 mm) and the same round pusher (radius 15 px). The expert is PushTExpert's idea carried over: every step,
# pick the contact on the T whose push best moves the block toward the goal pose, get behind it, push.
# Three differences from pusht_env shape the numbers below:
#   * The action is a position target, not a velocity. A PD controller (kp 100/s^2, kv 20/s, ten 0.01-s
#     physics steps per 0.1-s control step) pulls the pusher toward it; a target held d px ahead of the
#     pusher moves it at kp / kv * d = 5 d px/s. So a wanted velocity v (px/s) becomes the target
#     agent + _GP_LEAD * v, _GP_LEAD = kv / kp = 0.2 s.
#   * The block has no floor friction but no momentum either (pymunk damping 0: it stops after every
#     physics step), and the pusher's contact is frictionless. A push moves the block only while the pusher
#     presses, along the face's normal n, with the twist of an impulse on a free body: (n / m, (r x n) / I)
#     about the block's centre of gravity, m = 1, I = 3000 px^2.
#   * Success is gym-pusht's own: more than 95% of the goal T covered by the block (info["is_success"]),
#     and it ends the episode at once. A few px or a few degrees off fail, so the push slows near the goal.
# The observation is LeRobot's "environment_state_agent_pos", flattened: agent x, y (px) then the block's 8
# keypoints (16 floats, px). The block pose is recovered from the keypoints (block_pose_from_keypoints);
# the goal pose is gym-pusht's, fixed. The policy is Markov in the observation. Its steps are PushTExpert's
# 1-3 (score the candidate pushes, push or get behind the best one, orbit when the T is in the way), in
# pixels; its step 4 (back off and hold) is not needed, since success ends the episode.
_GP_KEYPOINTS = np.array(  # the 8 keypoints in the block's frame (px), in gym-pusht's order
    [(-60, 0), (60, 0), (60, 30), (-60, 30), (-15, 30), (15, 30), (15, 120), (-15, 120)], dtype=np.float64
)  # bar: x in [-60, 60], y in [0, 30]; stem: x in [-15, 15], y in [30, 120]
_GP_COG = np.array([0.0, 45.0])  # px, block frame: gym-pusht's centre of gravity (its 2 boxes' mean centre)
_GP_GOAL = np.array([256.0, 256.0, math.pi / 4])  # gym-pusht's goal pose: x, y (px), angle (rad)
_GP_R = 15.0  # px, pusher radius
_GP_K = 1.0 / 3000.0  # 1/px^2: mass / moment of inertia of the block (m = 1, I = 3000 px^2)
_GP_WALL = (7.0, 504.0)  # px: the walls' inner faces on both axes
_GP_LEAD = 0.2  # s: target = agent + _GP_LEAD * wanted velocity (kv / kp of gym-pusht's PD)
_GP_YAW_LEN = 120.0  # px per rad: how a yaw error weighs against a position error
_GP_STANDOFF = 12.0  # px: gap between pusher edge and block at the pre-contact point
_GP_CLEAR = 22.0  # px: edge clearance kept while orbiting the block
_GP_TRAVEL_COST = 0.002  # score per px of pusher travel to reach a candidate
_GP_V_PUSH = (20.0, 300.0)  # px/s, min and max pushing speed (fast far out, slow near the goal)
_GP_PUSH_GAIN = 3.0  # 1/s: pushing speed per px of remaining (scaled) twist error
_GP_V_MOVE = (100.0, 600.0)  # px/s, min and max repositioning speed
_GP_V_ORBIT = 200.0  # px/s: orbiting speed (slower: a target far ahead on the tangent cuts the T's corners)
_GP_MOVE_GAIN = 8.0  # 1/s: repositioning speed per px of distance to the pre-contact point


def block_pose_from_keypoints(kp16) -> tuple[float, float, float]:
    """gym-pusht's block pose (x, y, angle) from its 16 keypoint coordinates.

    gym-pusht makes keypoint i as R(angle) @ v_i + (x, y), v_i = _GP_KEYPOINTS[i], (x, y) the block body's
    position (its frame's origin, not its centre of gravity): the pose info["block_pose"] reports. The
    least-squares rigid fit (2-D Procrustes) inverts that exactly; the angle comes back in (-pi, pi].
    """
    w = np.asarray(kp16, dtype=np.float64).reshape(8, 2)
    lc = _GP_KEYPOINTS - _GP_KEYPOINTS.mean(axis=0)
    wc = w - w.mean(axis=0)
    angle = math.atan2(float(np.sum(lc[:, 0] * wc[:, 1] - lc[:, 1] * wc[:, 0])), float(np.sum(lc * wc)))
    c, s = math.cos(angle), math.sin(angle)
    x, y = w.mean(axis=0) - np.array([[c, -s], [s, c]]) @ _GP_KEYPOINTS.mean(axis=0)
    return float(x), float(y), angle


def keypoint_residual(kp16) -> np.ndarray:
    """How far (px) each row of 16 keypoint coordinates (N, 16) is from a rigid placement of the T: the
    largest distance of a keypoint from where block_pose_from_keypoints' fit puts it. The fit takes any
    16 numbers; this says whether they were a T (a scaled, collapsed or mirrored one is tens of px off).
    Vectorised apart from block_pose_from_keypoints, whose exact bytes the expert's actions depend on."""
    w = np.asarray(kp16, dtype=np.float64).reshape(-1, 8, 2)
    lc = _GP_KEYPOINTS - _GP_KEYPOINTS.mean(axis=0)
    wc = w - w.mean(axis=1, keepdims=True)
    cross = np.sum(lc[:, 0] * wc[..., 1] - lc[:, 1] * wc[..., 0], axis=1)
    angle = np.arctan2(cross, np.sum(lc * wc, axis=(1, 2)))
    c, s = np.cos(angle), np.sin(angle)
    rot = np.stack([np.stack([c, -s], axis=-1), np.stack([s, c], axis=-1)], axis=-2)  # (N, 2, 2)
    return np.linalg.norm(wc - lc @ rot.transpose(0, 2, 1), axis=2).max(axis=1)


def _gp_sdf(q: np.ndarray) -> np.ndarray:
    """Distance (px) from block-frame points q (..., 2) to the T (negative inside): the union of two boxes."""
    q = np.asarray(q, dtype=np.float64)
    d = np.inf
    for centre, half in (((0.0, 15.0), (60.0, 15.0)), ((0.0, 75.0), (15.0, 45.0))):
        a = np.abs(q - centre) - half
        out = np.linalg.norm(np.maximum(a, 0.0), axis=-1)
        d = np.minimum(d, out + np.minimum(np.max(a, axis=-1), 0.0))
    return d


def _gp_candidates() -> tuple[np.ndarray, np.ndarray]:
    """Contact points p (K, 2) and inward unit push directions n (K, 2), block frame (px)."""
    r = _GP_R
    pts, nrm = [], []

    def face(points, n):
        for p in points:
            pts.append(p)
            nrm.append(n)

    face([(x, 0.0) for x in np.linspace(-50.0, 50.0, 11)], (0.0, 1.0))  # bar's outer face
    for sgn in (-1.0, 1.0):
        face([(sgn * 60.0, y) for y in (7.0, 15.0, 23.0)], (-sgn, 0.0))  # bar ends
        face([(sgn * x, 30.0) for x in np.linspace(15.0 + r + 4.0, 54.0, 3)], (0.0, -1.0))  # bar underside
        face([(sgn * 15.0, y) for y in np.linspace(30.0 + r + 4.0, 114.0, 5)], (-sgn, 0.0))  # stem sides
    face([(x, 120.0) for x in (-10.0, 0.0, 10.0)], (0.0, -1.0))  # stem end
    # Convex corners: a round pusher on a corner can push along any direction in the corner's cone.
    corners = [((sgn * 60.0, 0.0), (sgn, 0.0), (0.0, -1.0)) for sgn in (-1.0, 1.0)]
    corners += [((sgn * 60.0, 30.0), (sgn, 0.0), (0.0, 1.0)) for sgn in (-1.0, 1.0)]
    corners += [((sgn * 15.0, 120.0), (sgn, 0.0), (0.0, 1.0)) for sgn in (-1.0, 1.0)]
    for p, a, b in corners:
        for w in (0.25, 0.5, 0.75):
            out = (1 - w) * np.array(a) + w * np.array(b)
            out /= np.linalg.norm(out)
            pts.append(p)
            nrm.append(tuple(-out))
    return np.array(pts, dtype=np.float64), np.array(nrm, dtype=np.float64)


class GymPushTExpert:
    """Scripted expert for gym-pusht: ``act(obs) -> float32[2]`` pusher position target (px), Markov in obs.

    ``obs`` is np.concatenate([agent_pos (2,), environment_state (16,)]) of gym-pusht's
    "environment_state_agent_pos" observation. ``noise`` is the std (px) of Gaussian noise added to every
    target, drawn from ``np.random.default_rng(seed)`` created once here; the target stays in [0, 512].
    """

    def __init__(self, noise: float = 0.0, seed: int = 0) -> None:
        self.noise = float(noise)
        self.seed = int(seed)
        self._rng = np.random.default_rng(self.seed)
        p, n = _gp_candidates()
        self._n = n
        self._t = np.stack([-n[:, 1], n[:, 0]], axis=1)  # tangent to each push direction
        self._contact = p - n * _GP_R  # pusher centre when touching (px)
        self._pre = p - n * (_GP_R + _GP_STANDOFF)  # pusher centre behind the contact (px)
        arm = p - _GP_COG
        tau = arm[:, 0] * n[:, 1] - arm[:, 1] * n[:, 0]  # torque arm (px) of a unit push
        u = np.concatenate([n, (_GP_YAW_LEN * _GP_K * tau)[:, None]], axis=1)
        self._u = u / np.linalg.norm(u, axis=1, keepdims=True)  # predicted twist directions
        self._seg = np.linspace(0.0, 1.0, 9)[1:-1]  # interior sample fractions of a path segment

    def reset(self) -> None:
        """Nothing to clear: the policy is memoryless (the noise generator keeps running)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        o = np.asarray(obs, dtype=np.float64)
        agent = o[0:2]
        target = agent + _GP_LEAD * self._velocity(agent, block_pose_from_keypoints(o[2:18]))
        if self.noise > 0.0:
            target = target + self._rng.normal(0.0, self.noise, size=2)
        return np.clip(target, 0.0, 512.0).astype(np.float32)

    def _velocity(self, agent: np.ndarray, pose: tuple[float, float, float]) -> np.ndarray:
        """The pusher velocity (px/s, world frame) PushTExpert's rules ask for."""
        x, y, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s], [s, c]])  # block frame -> world
        gc, gs = math.cos(_GP_GOAL[2]), math.sin(_GP_GOAL[2])
        goal_cog = _GP_GOAL[:2] + np.array([[gc, -gs], [gs, gc]]) @ _GP_COG
        bw = np.array([x, y])
        e = rot.T @ (goal_cog - (bw + rot @ _GP_COG))  # centre-of-gravity error, block frame (px)
        eyaw = wrap_angle(_GP_GOAL[2] - yaw)  # rad
        p = rot.T @ (agent - bw)  # pusher in the block frame (px)
        err = math.hypot(e[0], e[1])

        # 1-2. Score every candidate push against the desired twist.
        want = np.array([e[0], e[1], _GP_YAW_LEN * eyaw])
        want /= max(np.linalg.norm(want), 1e-9)
        align = self._u @ want
        pre_w = bw + self._pre @ rot.T
        reach = np.all((pre_w > _GP_WALL[0] + _GP_R + 5.0) & (pre_w < _GP_WALL[1] - _GP_R - 5.0), axis=1)
        # Travel: distance to the segment from pre-contact point to contact (the push funnel), so a
        # pusher already pushing at a candidate pays nothing to keep pushing there.
        rel = p - self._contact
        along = np.clip(np.einsum("kj,kj->k", rel, self._n), -_GP_STANDOFF, 0.0)
        travel = np.linalg.norm(rel - along[:, None] * self._n, axis=1)
        score = np.where(reach, align - _GP_TRAVEL_COST * travel, -np.inf)
        k = int(np.argmax(score))
        n, t, c0, g = self._n[k], self._t[k], self._contact[k], self._pre[k]

        # 3a. Behind the contact and on its line (within 6 px sideways, from 8 px behind the pre-contact
        # point to 10 px past the contact): push through it, steering back onto the line.
        rel = p - c0
        along, lat = float(rel @ n), float(rel @ t)
        if abs(lat) < 6.0 and -(_GP_STANDOFF + 8.0) < along < 10.0:
            twist_err = math.hypot(err, _GP_YAW_LEN * eyaw)  # px
            speed = min(max(_GP_PUSH_GAIN * twist_err, _GP_V_PUSH[0]), _GP_V_PUSH[1])
            return rot @ (speed * n - 5.0 * lat * t)
        # 3b. Path to the pre-contact point clear of the T: go straight there.
        dg = g - p
        dist = float(np.linalg.norm(dg))
        speed = min(max(_GP_MOVE_GAIN * dist, _GP_V_MOVE[0]), _GP_V_MOVE[1])
        path = p + self._seg[:, None] * dg
        # Clear = the path never comes closer to the T than the pusher is now (or than R + 2 px).
        floor = min(_GP_R + 2.0, float(_gp_sdf(p)) - 1.0)
        if np.all(_gp_sdf(path) > floor):
            return rot @ (min(speed, dist / _GP_LEAD) * dg / max(dist, 1e-9))
        # 3c. Otherwise orbit the T at a safe clearance, the shorter way round.
        grad = self._grad(p)
        tang = np.array([-grad[1], grad[0]])  # counter-clockwise around the T
        a_p = math.atan2(*(p - _GP_COG)[::-1])
        a_g = math.atan2(*(g - _GP_COG)[::-1])
        if wrap_angle(a_g - a_p) < 0.0:
            tang = -tang
        gap = float(_gp_sdf(p)) - _GP_R  # px between pusher edge and block
        radial = min(max(0.02 * (_GP_CLEAR - gap), -1.0), 1.0)  # saturates 50 px off the orbit
        v = tang + radial * grad
        return rot @ (_GP_V_ORBIT * v / max(np.linalg.norm(v), 1e-9))

    @staticmethod
    def _grad(p: np.ndarray) -> np.ndarray:
        """Unit outward gradient of the T's distance field at block-frame point p."""
        h = 1e-3
        q = np.array([p + (h, 0.0), p - (h, 0.0), p + (0.0, h), p - (0.0, h)])
        d = _gp_sdf(q)
        g = np.array([d[0] - d[1], d[2] - d[3]])
        nrm = np.linalg.norm(g)
        return g / nrm if nrm > 1e-12 else np.array([0.0, -1.0])
