"""The engine's geometry: object frames and arm targets in SE(3), as MimicGen's pose_utils has them.

A pose is a (4, 4) homogeneous matrix: rotation R (3, 3) top left, position p (3,) in metres (or the
task's own length unit) top right, [0, 0, 0, 1] below; an orientation is a rotation matrix (3, 3)
(quaternions, w first, only inside slerp). A planar task (a robot on a table, frames that turn about z
alone) gives its frames as (x, y, yaw) triples and its paths as (T, 2) points: the special case
z = 0, roll = pitch = 0, computed here with its own SE(2) arithmetic, so a planar task's bytes do not
depend on the 3-D path (tests/test_replay.py shows the two agree).

    transform_segment(points, vectors, src, new, rotations=None)   a path made relative to a frame at
        `src`, re-expressed for that frame at `new` (MimicGen's transform_source_data_segment_using_
        object_pose): points p' = M p, vectors v' = R_M v, rotations R' = R_M R, with M = new src^-1
    transform_sliding(points, vectors, srcs, news, rotations=None)   the same for a path whose frame
        slides (step t from srcs[t] to news[t]), all steps' products at once, each step's bits its own
    transform_pose(pose, src, new)   a pose made relative to a frame at `src` (an object's, say),
                             re-expressed for that frame at `new`: the pose M pose, M = new src^-1
    pose_gap(a, b)           how far apart two poses are: (distance, angle in rad)
    interpolate(a, b, s)     the pose a fraction s of the way from a to b: position linear, orientation
                             by slerp (planar: yaw the short way); interpolate_path(a, b, fractions) and
                             slerp_path(r0, r1, fractions) a path's, its ends' quaternions found once
    planar_pose(x, y, yaw)   the (4, 4) pose of a planar frame
    rotation_of(q)           a quaternion's rotation matrix; rotations_of(qs) a stack's, row for row
    solve(a, b)              np.linalg.solve(a, b) for float64 systems known to be well posed (an inverse
                             kinematics' damped J J^T + lambda^2 I), its bits without its checks
"""

from __future__ import annotations

import math

import numpy as np
from numpy.linalg import _umath_linalg

__all__ = [
    "interpolate",
    "interpolate_path",
    "is_planar",
    "planar_pose",
    "pose_gap",
    "quat_of",
    "rigid_inverse",
    "rotation",
    "rotation_angle",
    "rotation_of",
    "rotations_of",
    "slerp",
    "slerp_path",
    "solve",
    "transform_pose",
    "transform_segment",
    "transform_sliding",
]


def rotation(yaw: float) -> np.ndarray:
    """The 2x2 rotation by `yaw` (rad)."""
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s], [s, c]])


def is_planar(pose) -> bool:
    """Whether `pose` is a planar frame, an (x, y, yaw) triple, rather than a (4, 4) matrix."""
    return np.shape(pose) == (3,)


def planar_pose(x: float, y: float, yaw: float, z: float = 0.0) -> np.ndarray:
    """The (4, 4) pose of the planar frame (x, y, yaw), at height z."""
    out = np.eye(4)
    out[:2, :2] = rotation(yaw)
    out[:3, 3] = (x, y, z)
    return out


def _matrix(pose) -> np.ndarray:
    return planar_pose(*(float(v) for v in pose)) if is_planar(pose) else np.asarray(pose, np.float64)


def rigid_inverse(pose) -> np.ndarray:
    """The inverse of a (4, 4) pose, [R^T, -R^T p], or of each of a stack (N, 4, 4): exact where a general
    inverse rounds (an unmoved frame gives the identity, so a replay at zero perturbation commands the
    source's own targets)."""
    pose = np.asarray(pose, np.float64)
    rot, pos = pose[..., :3, :3], pose[..., :3, 3:]  # pos (..., 3, 1)
    out = np.zeros(pose.shape)
    out[..., :3, :3], out[..., :3, 3:], out[..., 3, 3] = rot.mT, -(rot.mT @ pos), 1.0
    return out


def transform_segment(points, vectors, src_pose, new_pose, rotations=None):
    """Re-express a path that was made relative to an object at `src_pose` for the object at `new_pose`.

    Planar (both poses (x, y, yaw) triples): points (T, 2) world positions and vectors (T, 2) world
    velocities; a point is first written in the source object's frame, q = R(-yaw0) (p - xy0), then put
    back in the world from the new pose, p' = R(yaw1) q + xy1; a velocity only rotates, v' = R(yaw1 -
    yaw0) v (the SE(2) analog of MimicGen's transform_source_data_segment_using_object_pose).
    SE(3) (either pose a (4, 4) matrix): points (T, 3), vectors (T, 3) or None, rotations (T, 3, 3) or
    None (the arm's orientation along the path): with M = new src^-1, p' = M p, v' = R_M v, R' = R_M R.
    Returns (points', vectors') planar, (points', vectors', rotations') in SE(3) (None stays None); an
    identical pose returns the inputs (to float rounding).
    """
    if is_planar(src_pose) and is_planar(new_pose) and rotations is None:
        x0, y0, yaw0 = (float(v) for v in src_pose)
        x1, y1, yaw1 = (float(v) for v in new_pose)
        in_object = (np.asarray(points, np.float64) - (x0, y0)) @ rotation(-yaw0).T  # (T, 2) object frame
        moved = in_object @ rotation(yaw1).T + (x1, y1)
        turned = np.asarray(vectors, np.float64) @ rotation(yaw1 - yaw0).T
        return moved, turned
    src, new = _matrix(src_pose), _matrix(new_pose)
    rel = new @ rigid_inverse(src)  # (4, 4): the world moved with the object
    turn = rel[:3, :3]
    moved = np.asarray(points, np.float64).reshape(-1, 3) @ turn.T + rel[:3, 3]
    turned = None if vectors is None else np.asarray(vectors, np.float64).reshape(-1, 3) @ turn.T
    spun = None if rotations is None else turn @ np.asarray(rotations, np.float64)  # (T, 3, 3)
    return moved, turned, spun


def transform_sliding(points, vectors, src_poses, new_poses, rotations=None):
    """transform_segment for a path whose object frame moves along it (a frame sliding onto another): frame
    t re-expressed from src_poses[t] to new_poses[t]; row t is transform_segment of row t alone, bit for
    bit. SE(3) (poses (T, 4, 4)): every frame's M_t = new_t src_t^-1 and products at once, each a stack of
    the frames' own; planar triples frame by frame."""
    if is_planar(src_poses[0]) and is_planar(new_poses[0]) and rotations is None:
        rows = [
            transform_segment(points[t : t + 1], vectors[t : t + 1], was, now)
            for t, (was, now) in enumerate(zip(src_poses, new_poses))
        ]
        return tuple(np.concatenate(part) for part in zip(*rows))
    src, new = np.asarray(src_poses, np.float64), np.asarray(new_poses, np.float64)
    rel = new @ rigid_inverse(src)  # (T, 4, 4)
    turn = rel[:, :3, :3]
    moved = (np.asarray(points, np.float64).reshape(-1, 1, 3) @ turn.mT)[:, 0] + rel[:, :3, 3]
    turned = None if vectors is None else (np.asarray(vectors, np.float64).reshape(-1, 1, 3) @ turn.mT)[:, 0]
    spun = None if rotations is None else turn @ np.asarray(rotations, np.float64)  # (T, 3, 3)
    return moved, turned, spun


def transform_pose(pose, src_pose, new_pose):
    """`pose` (a frame's pose where an object's frame was at `src_pose`) re-expressed for the object's frame
    at `new_pose`, as transform_segment moves a path: planar, an (x, y, yaw) triple (its yaw turned by
    yaw1 - yaw0); in SE(3), the (4, 4) pose M pose, M = new src^-1."""
    if is_planar(pose) and is_planar(src_pose) and is_planar(new_pose):
        (xy,), _ = transform_segment([np.asarray(pose[:2], np.float64)], np.zeros((1, 2)), src_pose, new_pose)
        return np.array([xy[0], xy[1], float(pose[2]) + float(new_pose[2]) - float(src_pose[2])])
    return _matrix(new_pose) @ rigid_inverse(_matrix(src_pose)) @ _matrix(pose)


def pose_gap(a, b) -> tuple[float, float]:
    """(distance between the two poses' positions, angle in rad of the rotation from a's orientation to
    b's): planar triples give the xy distance and the yaw difference wrapped to [0, pi]."""
    if is_planar(a) and is_planar(b):
        shift = np.asarray(b) - np.asarray(a)
        return math.hypot(shift[0], shift[1]), abs(math.remainder(shift[2], math.tau))
    a, b = _matrix(a), _matrix(b)
    return float(np.linalg.norm(b[:3, 3] - a[:3, 3])), rotation_angle(a[:3, :3], b[:3, :3])


def rotation_angle(r0, r1) -> float:
    """The angle (rad) of the rotation that takes orientation r0 (3, 3) to r1."""
    return math.acos(min(1.0, max(-1.0, (float(np.trace(np.asarray(r0).T @ r1)) - 1) / 2)))


def quat_of(rot) -> np.ndarray:
    """The unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (3, 3) (Shepperd's method)."""
    m = np.asarray(rot, np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 0.0))
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i], q[1 + j], q[1 + k] = 0.25 * s, (m[j, i] + m[i, j]) / s, (m[k, i] + m[i, k]) / s
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def _rotation_rows(w, x, y, z) -> list:
    """The rows of a unit quaternion's rotation matrix, for numbers or for arrays of them alike."""
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def rotation_of(q) -> np.ndarray:
    """The rotation matrix (3, 3) of a quaternion (w, x, y, z) (normalised first)."""
    return np.array(_rotation_rows(*(np.asarray(q, np.float64) / np.linalg.norm(q))))


def rotations_of(qs) -> np.ndarray:
    """The rotation matrices (N, 3, 3) of quaternions (N, 4) (w, x, y, z), each normalised first: row i is
    rotation_of(qs[i]), bit for bit (its norm the same BLAS dot, in float32 for float32 quaternions as
    np.linalg.norm takes it, the rest elementwise)."""
    raw = np.asarray(qs).reshape(-1, 4)
    raw = raw if raw.dtype.kind == "f" else raw.astype(np.float64)
    norm = np.sqrt(raw[:, None, :] @ raw[:, :, None])[:, 0]  # (N, 1)
    rows = _rotation_rows(*(raw.astype(np.float64) / norm).T)
    return np.array(rows).transpose(2, 0, 1).copy()  # C order: each (3, 3) laid out as one alone, for BLAS


def slerp_path(r0, r1, fractions) -> np.ndarray:
    """The rotations (N, 3, 3) each fraction s (0..1) of `fractions` of the way from r0 to r1 along the
    shorter arc: the ends' quaternions found once for the whole path."""
    q0, q1 = quat_of(r0), quat_of(r1)
    dot = float(q0 @ q1)
    if dot < 0:  # q and -q are one rotation: take the short way
        q1, dot = -q1, -dot
    s = np.asarray(fractions, np.float64).reshape(-1, 1)
    if dot > 1 - 1e-12:
        return rotations_of(q0 + s * (q1 - q0))
    theta = math.acos(min(dot, 1.0))
    w0 = np.array([math.sin((1 - f) * theta) for f in s[:, 0].tolist()]).reshape(-1, 1)
    w1 = np.array([math.sin(f * theta) for f in s[:, 0].tolist()]).reshape(-1, 1)
    return rotations_of((w0 * q0 + w1 * q1) / math.sin(theta))


def slerp(r0, r1, s: float) -> np.ndarray:
    """The rotation (3, 3) a fraction s (0..1) of the way from r0 to r1 along the shorter arc."""
    return slerp_path(r0, r1, (s,))[0]


def interpolate_path(a, b, fractions):
    """The poses each fraction s (0..1) of `fractions` of the way from a to b: planar triples give a list
    of triples (x, y linear; yaw the short way), (4, 4) poses an (N, 4, 4) array (position linear,
    orientation by slerp_path)."""
    if is_planar(a) and is_planar(b):
        dyaw = math.remainder(float(b[2]) - float(a[2]), math.tau)
        return [
            (a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), float(a[2]) + s * dyaw) for s in fractions
        ]
    a, b = _matrix(a), _matrix(b)
    s = np.asarray(fractions, np.float64).reshape(-1, 1)
    out = np.zeros((len(s), 4, 4))
    out[:, :3, :3] = slerp_path(a[:3, :3], b[:3, :3], s[:, 0])
    out[:, :3, 3] = a[:3, 3] + s * (b[:3, 3] - a[:3, 3])
    out[:, 3, 3] = 1.0
    return out


def interpolate(a, b, s: float):
    """The pose a fraction s (0..1) of the way from a to b (interpolate_path's one pose)."""
    return interpolate_path(a, b, (s,))[0]


def solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.linalg.solve(a, b) of float64 arrays, the same bits: the LAPACK gufunc it calls, without its
    checks and error-state context (~10 us a call, which a Python IK loop pays dozens of times a frame).
    For a system known to be well posed (a damped least squares' J J^T + lambda^2 I, positive definite):
    a singular `a` is not reported."""
    return (_umath_linalg.solve1 if b.ndim == 1 else _umath_linalg.solve)(a, b, signature="dd->d")
