"""The engine's one replay, for every task: MimicGen's generation loop (its data_generator.py), with the
task only describing (datagen.task.Task and its ReplaySpec, `task.replay` (called spec below): arms,
subtasks, bridges, hold, follow tolerance and the action kind; the task's frames and signals).

    plan = cut(task, source)                # the source's subtasks: [Segment], by the task's signals
    run = Replay(task, source, plan, start)  # one attempt: run.act(obs, env) its actions, run.outcome(...)
    e = nearest(task, pool, start)          # MimicGen's nearest source selection

A source is cut into spec.subtasks at its signals: a subtask with `ends` stops at the first frame
after its start at which that signal turns on, found by re-simulating the source from its first frame
through its recorded actions (the signals live in the physics, not in the 10 Hz frames), as MimicGen's
prepare_src_dataset annotates a source through its env. The last subtask runs to the source's end.

An attempt is executed subtask by subtask. At each subtask's start, the object frames are read from the
current observation (open loop in between, as MimicGen reads the object pose once per subtask), and every
arm's segment (the source's targets: spec.action.to_target) is re-expressed from its frame's pose in the
source (at the subtask's first frame) into the same frame's pose now (datagen.poses.transform_segment; a
subtask's `onto` makes an arm's frame slide onto another over the subtask). A subtask with `bridge` is
entered by linear interpolation from where the arms are to their first waypoints, all arms in step, at up
to spec.bridge_speed (none when every arm is within spec.bridge_tol); each gripper keeps its last command.
Then every step is spec.action.to_action of each arm's waypoint, velocity and gripper command of that
frame. Mode "replay_live" (Replay's follow, spec.follow_tol) follows the objects' live poses: before each
step of a subtask every object frame of it is read, and once one lies beyond follow from where the segment
as re-expressed expects it (the source's own pose of that frame, moved as the waypoints were), the rest of
the segment is re-expressed from the poses now, as its start was (a frame sliding onto another slides
again from there over the remaining frames): still no expert, only the source's path relative to its
objects. After the last subtask the arms hold still for spec.hold_steps steps (so a success that must be
held can complete). The attempt is kept only on the env's success; otherwise the first reason of
REASONS that applies:

    path_out_of_reach     a re-expressed waypoint lies beyond its arm's reach (spec.reach)
    approach_blocked      a bridge moved the object (task.object_pose) beyond spec.bridge_moves
    <signal>_missed       a subtask's end signal never came on (in the task's subtask order)
    out_of_time           the episode ended before the plan did
    finished_off_target   the plan ran to its end without success
    source_not_split      the source cannot be cut into the task's subtasks (cut raises ValueError)

One attempt is a Replay whose act(obs, env) gives each action from each observation (None once its plan
and hold are done); the engine's one attempt runner executes it (datagen.lockstep.Replaying), one
attempt at a time or many in lanes, the same bytes; datagen.lockstep.replay_from replays a source from a
given start.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, replace

import numpy as np

from datagen.poses import (
    interpolate_path,
    pose_gap,
    rotation_angle,
    slerp_path,
    transform_pose,
    transform_segment,
    transform_sliding,
)
from datagen.task import POSE_SHAPES, Outcome, Source, Subtask, Task, ended, owed

__all__ = ["Replay", "Segment", "cut", "nearest", "plan_of", "signals"]


@dataclass(frozen=True)
class Segment:
    """One subtask of a source demo: its frames [start, stop)."""

    subtask: Subtask
    start: int
    stop: int


def signals(task: Task, source: Source, env=None) -> np.ndarray:
    """(T+1, n) bool: the task's signals (the ends of its subtasks, in order) at each frame of `source`
    and after its last action (the last row repeats the last frame's when read from the frames). Read
    from the recorded frames where the task's signals need no physics (spec.resimulate False); else
    re-simulated from its first frame through its recorded actions, and a ValueError when that leaves
    the recorded frames by more than 1 mm (a set from another env)."""
    names = [s.ends for s in task.replay.subtasks if s.ends]
    if not task.replay.resimulate:
        on = [[task.signals(obs, None)[n] for n in names] for obs in source.states]
        return np.array(on + on[-1:], bool).reshape(len(on) + 1, len(names))
    env = task.make_env() if env is None else env
    obs = task.place(env, task.start_of(source.states[0]))
    on = [[task.signals(obs, env)[n] for n in names]]
    drift = 0.0
    for t, a in enumerate(source.actions):
        obs, *_ = env.step(a)
        on.append([task.signals(obs, env)[n] for n in names])
        if t + 1 < len(source.states):
            drift = max(drift, float(np.max(np.abs(obs - source.states[t + 1]))))
    if drift > 1e-3:
        raise ValueError(f"source episode {source.episode} does not re-simulate (max drift {drift:.4f})")
    return np.array(on, bool).reshape(len(on), len(names))


def cut(task: Task, source: Source, env=None) -> list[Segment]:
    """The source's frames cut into spec.subtasks: each subtask with an end signal stops at that signal's
    first rising edge after its start (signals), the last one at the source's end. Raises ValueError
    when a signal never rises there (the source does not show that subtask)."""
    n = len(source.actions)
    on = signals(task, source, env) if any(s.ends for s in task.replay.subtasks) else None
    out, start, i = [], 0, 0
    for sub in task.replay.subtasks:
        stop = n
        if sub.ends:
            rise = np.flatnonzero(on[start + 1 : n, i] & ~on[start : n - 1, i])
            if not len(rise):
                why = f"{sub.ends!r} never comes on after frame {start}"
                raise ValueError(f"source episode {source.episode}: {why}")
            stop, i = start + 1 + int(rise[0]), i + 1
        out.append(Segment(sub, start, stop))
        start = stop
    return out


def plan_of(task: Task, source: Source, plans: dict | None = None) -> list[Segment]:
    """cut(task, source), kept in `plans` (a worker's cache, datagen.engine.Simulators.plans) under the
    task, its subtasks and the sha256 of the source's frames: a plan is a pure function of them."""
    if plans is None:
        return cut(task, source)
    h = hashlib.sha256(np.ascontiguousarray(source.states).tobytes())
    h.update(np.ascontiguousarray(source.actions).tobytes())
    key = (task.name, task.replay.subtasks, source.episode, h.hexdigest())
    if key not in plans:
        plans[key] = cut(task, source)
    return plans[key]


def nearest(task: Task, pool: dict, start) -> int:
    """MimicGen's nearest selection: the episode of the source in `pool` ({episode: Source}) whose start's
    objects lie nearest `start`'s (task.start_distance); ties go to the lowest episode index."""
    return min(pool, key=lambda e: (task.start_distance(task.start_of(pool[e].states[0]), start), e))


def _moved(points, vectors, rotations, was, now):
    """transform_segment's (points, vectors, rotations) for both of its shapes (planar: no rotations)."""
    got = transform_segment(points, vectors, was, now, rotations)
    return got if len(got) == 3 else (*got, None)


class Replay:
    """One attempt's replay of `plan` (a source's Segments) from `start`: what it found so far and its
    steps (see the module docstring)."""

    def __init__(self, task: Task, source: Source, plan: list[Segment], start, follow=None):
        self.task, self.source, self.plan, self.start = task, source, plan, start
        # (length, rad), spec.follow_tol: re-express the rest of a segment from the object frames' live
        # poses once one drifts this far from where the segment expects it (None: open loop)
        self.follow = follow
        self.reanchored = 0  # how often the rest of a segment was re-expressed from live poses
        self._source_poses = {}  # frame -> its pose in every source frame (follow's expectations)
        self.out_of_reach = False  # a re-expressed waypoint beyond its arm's reach
        self.blocked = False  # a bridge moved the object
        self.seen = dict.fromkeys((s.ends for s in task.replay.subtasks if s.ends), False)  # signals ever on
        self.planned = False  # the plan ran to its end with the episode still going
        self.bridging = None  # the object pose a bridge under way started from
        self.current = None  # the subtask under way
        self.beyond = None  # where the first waypoint beyond reach was found, in words
        self.bumped = None  # which bridge moved the object, in words
        # where act() is: its phase ("new", "start" of a subtask, "bridge", "frames", "hold", "done"), and
        # what each gripper and each arm's orientation was last told
        self._phase, self._grips, self._turns = "new", None, None

    def segment(self, seg: Segment, now) -> dict:
        """{arm: (waypoints (T, d), velocities (T, d) or None, gripper commands (T,) or None, orientations
        (T, 3, 3) or None)} of `seg`, re-expressed for the frames in the observation `now`."""
        task, src = self.task, self.source
        rows = slice(seg.start, seg.stop)
        targets = task.replay.action.to_target(task, src.states[rows], src.actions[rows])
        first, out = src.states[seg.start], {}
        onto = seg.subtask.onto or (None,) * len(task.replay.arms)
        for arm, frame, to in zip(task.replay.arms, seg.subtask.frames, onto):
            pts, vel, grip, *turns = targets[arm]
            rots = turns[0] if turns else None
            if to is None:
                was, now_ = task.frame_pose(frame, first), task.frame_pose(frame, now)
                pts, vel, rots = _moved(pts, vel, rots, was, now_)
            else:  # a frame sliding from `frame` onto `to` over the subtask
                a0, a1 = task.frame_pose(frame, first), task.frame_pose(to, first)
                b0, b1 = task.frame_pose(frame, now), task.frame_pose(to, now)
                k = max(len(pts) - 1, 1)
                way = [t / k for t in range(len(pts))]  # frame t in the pose a fraction t / k of the way
                was, now_ = interpolate_path(a0, a1, way), interpolate_path(b0, b1, way)
                pts, vel, *rest = transform_sliding(pts, vel, was, now_, rots)
                rots = rest[0] if rest else None
            out[arm] = (pts, vel, None if grip is None else np.asarray(grip, np.float64), rots)
        return out

    def watch(self, obs, env) -> None:
        """Record which of the task's signals are on in the observation `obs` of `env`."""
        if not self.seen:
            return
        for name, on in self.task.signals(obs, env).items():
            if name in self.seen:
                self.seen[name] |= bool(on)

    def expected(self, seg: Segment, now) -> dict:
        """{frame: its pose at each of seg's frames} for every object frame of seg's subtask: where the
        segment re-expressed for the observation `now` expects it, the source's own poses of that frame
        moved as segment moves the waypoints (a frame that slides onto another: the pose of that step)."""
        task, first, out = self.task, self.source.states[seg.start], {}
        onto = seg.subtask.onto or (None,) * len(task.replay.arms)
        for frame, to in zip(seg.subtask.frames, onto):
            if frame in out:
                continue
            if frame not in self._source_poses:
                self._source_poses[frame] = [task.frame_pose(frame, s) for s in self.source.states]
            poses = self._source_poses[frame][seg.start : seg.stop]
            a0, b0 = task.frame_pose(frame, first), task.frame_pose(frame, now)
            if to is None:
                out[frame] = [transform_pose(p, a0, b0) for p in poses]
                continue
            a1, b1 = task.frame_pose(to, first), task.frame_pose(to, now)
            way = [t / max(len(poses) - 1, 1) for t in range(len(poses))]
            out[frame] = [
                transform_pose(p, was, now_)
                for p, was, now_ in zip(poses, interpolate_path(a0, a1, way), interpolate_path(b0, b1, way))
            ]
        return out

    def drifted(self, expect: dict, i: int, obs) -> bool:
        """Whether an object frame in `obs` lies farther than self.follow from where `expect` (expected's)
        puts it at its step i."""
        far, turned = self.follow
        for frame, poses in expect.items():
            d, a = pose_gap(poses[i], self.task.frame_pose(frame, obs))
            if d > far or a > turned:
                return True
        return False

    def check_reach(self, segs: dict) -> None:
        """Note (once) the first re-expressed waypoint of `segs` beyond its arm's reach."""
        for arm, (pts, *_) in segs.items():
            inside = self.task.replay.in_reach(arm, pts)
            if not inside.all() and not self.out_of_reach:
                i = int(np.argmin(inside))
                at_ = ", ".join(f"{v:.4g}" for v in pts[i])
                self.beyond = (
                    f"subtask {self.current!r}: waypoint {i} of {len(pts)} for arm {arm} ({at_}) "
                    "is beyond its reach"
                )
            self.out_of_reach |= not inside.all()

    def act(self, obs, env):
        """The attempt's next action for the observation `obs` of `env` (the first, then the one after each
        step), or None once the plan and the hold are done (the runner then ends the attempt; it stops
        asking when the episode ends). Each call after the first records the signals `obs` shows (watch),
        then the attempt moves on through its phases until it has an action: a subtask's start (its
        segment re-expressed for the frames now), its bridge, its frames, then the hold. With
        self.follow, before each frame of a segment the object frames are read: once one has drifted
        beyond it from where the segment expects it, the segment's remaining frames are re-expressed
        from the poses now (re-anchored)."""
        if self._phase != "new":
            self.watch(obs, env)
        else:
            self._phase, self._next = "start", 0  # the plan's next subtask
        while True:
            if self._phase == "start":  # a subtask starts, or the plan is done
                if self._next == len(self.plan):
                    self.planned, self._phase, self._held = True, "hold", 0
                else:
                    self._start(self.plan[self._next], obs, env)
                    self._next += 1
            elif self._phase == "bridge":  # linear interpolation (orientation: slerp), all arms in step
                if self._i < self._n:
                    return self._bridge_action(obs)
                self.end_bridge(obs)
                self._phase, self._t, self._at = "frames", 0, 0
            elif self._phase == "frames":
                if self._t < self._seg.stop - self._seg.start:
                    return self._frame_action(obs)
                self._phase = "start"
            elif self._phase == "hold":  # hold still so a success hold can complete
                spec = self.task.replay
                if self._held < spec.hold_steps:
                    self._held += 1
                    here = {a: self.task.arm_pose(a, obs, env)[0] for a in spec.arms}
                    still = {a: np.zeros(len(here[a])) for a in spec.arms}
                    return spec.action.to_action(self.task, obs, here, still, self._grips, self._turns)
                self._phase = "done"
            else:
                return None

    def _start(self, seg: Segment, obs, env) -> None:
        """Subtask `seg` starts at the observation `obs`: its segment re-expressed for the frames now, its
        reach checked, and its bridge planned (phase "bridge"; "frames" when it has none)."""
        task = self.task
        self.current, self._seg = seg.subtask.name, seg
        # a user's task's poses, checked once a subtask: a NaN or the wrong shape is one line
        owed(task, "object_pose", task.object_pose(obs), *POSE_SHAPES)
        for frame in dict.fromkeys((*seg.subtask.frames, *(f for f in seg.subtask.onto or () if f))):
            owed(task, f"frame_pose({frame!r})", task.frame_pose(frame, obs), *POSE_SHAPES)
        self._segs = segs = self.segment(seg, obs)
        some = segs[next(iter(segs))]  # what every arm's segment holds: velocities? grips? orientations?
        self._moving, gripping, self._turning = (some[i] is not None for i in (1, 2, 3))
        self.check_reach(segs)
        self._expect = self.expected(seg, obs) if self.follow is not None else None
        if self._grips is None and gripping:
            self._grips = {a: float(segs[a][2][0]) for a in task.replay.arms}
        self._phase, self._t, self._at = "frames", 0, 0
        if seg.subtask.bridge:
            poses = {a: task.arm_pose(a, obs, env) for a in task.replay.arms}
            self._here = {a: p for a, (p, _) in poses.items()}
            self._first = {a: segs[a][0][0] for a in task.replay.arms}
            self._facing = {a: r for a, (_, r) in poses.items()}
            self._aims = {a: segs[a][3][0] for a in task.replay.arms} if self._turning else None
            speed = self.bridge_speed(segs)
            self._n = self.bridge_steps(self._here, self._first, self._facing, self._aims, speed)
            if self._turning:
                self._turn_path = {
                    a: self.turns(self._facing[a], self._aims[a], self._n) for a in task.replay.arms
                }
            self._i, self._phase = 0, "bridge"
            self.bridging = task.object_pose(obs)

    def _bridge_action(self, obs) -> np.ndarray:
        """Step i of n of the bridge: each arm a fraction i / n of the way to its first waypoint, at the
        bridge's speed, each gripper holding its last command."""
        task, i, n, here, first = self.task, self._i, self._n, self._here, self._first
        self._i += 1
        wp = {a: here[a] + i / n * (first[a] - here[a]) for a in task.replay.arms}
        vel = {a: (first[a] - here[a]) * task.spec.fps / n for a in task.replay.arms}
        if self._turning:
            self._turns = {a: self._turn_path[a][i] for a in task.replay.arms}
        grips = None if self._grips is None else dict(self._grips)
        return task.replay.action.to_action(task, obs, wp, vel, grips, self._turns)

    def _frame_action(self, obs) -> np.ndarray:
        """Frame t of the segment: its re-expressed waypoint, velocity, gripper command and orientation
        (re-anchored first when an object frame has drifted beyond follow)."""
        task, seg, t = self.task, self._seg, self._t
        self._t += 1
        if self._expect is not None and self.drifted(self._expect, t - self._at, obs):
            rest = Segment(seg.subtask, seg.start + t, seg.stop)
            self._segs, self._expect, self._at = self.segment(rest, obs), self.expected(rest, obs), t
            self.reanchored += 1
            self.check_reach(self._segs)
        segs, i = self._segs, t - self._at
        if self._grips is not None:
            self._grips = {a: float(segs[a][2][i]) for a in task.replay.arms}
        if self._turning:
            self._turns = {a: segs[a][3][i] for a in task.replay.arms}
        wp = {a: segs[a][0][i] for a in task.replay.arms}
        vel = {a: segs[a][1][i] for a in task.replay.arms} if self._moving else None
        return task.replay.action.to_action(task, obs, wp, vel, self._grips, self._turns)

    def bridge_steps(self, here: dict, first: dict, facing: dict, turns: dict | None, speed: float) -> int:
        """Steps of the bridge from the arms at `here` (positions, orientations `facing`) to their first
        waypoints `first` (orientations `turns`): the farthest arm at `speed`, or the most
        turned at spec.bridge_turn_speed where the task sets one; 0 when every arm is within bridge_tol."""
        task = self.task
        fps = task.spec.fps
        gaps = [first[a] - here[a] for a in task.replay.arms]  # a planar gap's length as np.hypot gives it
        dist = max(float(np.hypot(*g)) if len(g) == 2 else float(np.linalg.norm(g)) for g in gaps)
        n = math.ceil(dist / (speed / fps) - 1e-9) if dist > task.replay.bridge_tol else 0
        if turns is not None and task.replay.bridge_turn_speed is not None:
            angle = max(
                rotation_angle(facing[a], turns[a]) for a in task.replay.arms if facing[a] is not None
            )
            n = max(n, math.ceil(angle / (task.replay.bridge_turn_speed / fps) - 1e-9))
        return n

    def bridge_speed(self, segs: dict) -> float:
        """spec.bridge_speed, or where the task sets none, the source's own top speed over `segs` (each
        arm's waypoints, frame to frame): a bridge then moves no faster than the demo did."""
        if self.task.replay.bridge_speed is not None:
            return self.task.replay.bridge_speed
        steps = [np.linalg.norm(np.diff(pts, axis=0), axis=1) for pts, *_ in segs.values() if len(pts) > 1]
        top = max((float(s.max()) for s in steps if len(s)), default=0.0) * self.task.spec.fps
        return top if top > 0 else math.inf

    @staticmethod
    def turns(facing, toward, n: int) -> list:
        """The orientations of a bridge's n steps, step i a fraction i / n of the way from `facing` to
        `toward` (facing None: not known, so `toward`)."""
        return [toward] * n if facing is None else slerp_path(facing, toward, [i / n for i in range(n)])

    def end_bridge(self, obs) -> None:
        """Whether the bridge that started at self.bridging moved the object beyond spec.bridge_moves."""
        tol = self.task.replay.bridge_moves
        if self.bridging is not None and tol is not None:
            moved, turned = pose_gap(self.bridging, self.task.object_pose(obs))
            if (moved > tol[0] or turned > tol[1]) and not self.blocked:
                self.bumped = (
                    f"subtask {self.current!r}: its bridge moved the object {moved:.4g} and turned it "
                    f"{turned:.3g} rad"
                )
            self.blocked |= moved > tol[0] or turned > tol[1]
        self.bridging = None

    def outcome(self, env, last_obs, episode: dict) -> Outcome:
        """The Outcome of the frames `episode` recorded (last_obs: the observation after its last step)."""
        self.watch(last_obs, env)
        if self.bridging is not None:  # the episode ended during a bridge
            self.end_bridge(last_obs)
        success = bool(self.task.success(env))
        missed = [name for name, on in self.seen.items() if not on]
        where = f"subtask {self.current!r}"  # the subtask under way when it failed
        if success:
            why, detail = None, None
        elif self.out_of_reach:
            why, detail = "path_out_of_reach", self.beyond
        elif self.blocked:
            why, detail = "approach_blocked", self.bumped
        elif missed:
            ending = next(s.name for s in self.task.replay.subtasks if s.ends == missed[0])
            why, detail = f"{missed[0]}_missed", f"subtask {ending!r}: its end signal never came on"
        elif not self.planned:
            why, detail = "out_of_time", f"{where}: the episode's {self.task.spec.max_steps} steps ran out"
        else:
            why, detail = "finished_off_target", f"{where}: its last waypoint reached without success"
        got = ended(episode | {"success": success}, why, self.start, self.source.episode)
        return replace(got, detail=detail)
