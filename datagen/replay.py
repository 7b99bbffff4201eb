"""The engine's one replay, for every task: MimicGen's generation loop (its data_generator.py), with the
task only describing (datagen.task.Task: arms, subtasks, frames, signals, the action conversion).

    plan = cut(task, source)                      # the source's subtasks: [Segment], by the task's signals
    got = replay(task, env, start, source, plan)  # an Outcome: reason None (kept) or why not
    e = nearest(task, pool, start)                # MimicGen's nearest source selection

A source is cut into the task's subtasks at its signals: a subtask with `ends` stops at the first frame
after its start at which that signal turns on, found by re-simulating the source from its first frame
through its recorded actions (the signals live in the physics, not in the 10 Hz frames), as MimicGen's
prepare_src_dataset annotates a source through its env. The last subtask runs to the source's end.

An attempt is executed subtask by subtask. At each subtask's start, the object frames are read from the
current observation (open loop in between, as MimicGen reads the object pose once per subtask), and every
arm's segment (the source's targets: task.action_to_target) is re-expressed from its frame's pose in the
source (at the subtask's first frame) into the same frame's pose now (datagen.task.transform_segment; a
subtask's `onto` makes an arm's frame slide onto another over the subtask). A subtask with `bridge` is
entered by linear interpolation from where the arms are to their first waypoints, all arms in step, at up
to task.bridge_speed (none when every arm is within task.bridge_tol); each gripper keeps its last command.
Then every step is task.target_to_action of each arm's waypoint, velocity and gripper command of that
frame. After the last subtask the arms hold still for task.hold_steps steps (so a success that must be
held can complete). The attempt is kept only on the env's success; otherwise the first reason of
REASONS that applies:

    path_out_of_reach     a re-expressed waypoint lies beyond its arm's reach (task.reach)
    approach_blocked      a bridge moved the object (task.object_pose) beyond task.bridge_moves
    <signal>_missed       a subtask's end signal never came on (in the task's subtask order)
    out_of_time           the episode ended before the plan did
    finished_off_target   the plan ran to its end without success
    source_not_split      the source cannot be cut into the task's subtasks (cut raises ValueError)

One attempt is a generator (Replay.steps) that receives each observation and yields each action, so the
same code runs one attempt at a time (replay) and as lockstep's lanes (datagen.lockstep.replay_lanes):
the same bytes.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass

import numpy as np

from datagen.task import Outcome, Source, Subtask, Task, ended, recorded, transform_segment

__all__ = ["Replay", "Segment", "cut", "nearest", "plan_of", "replay", "signals"]


@dataclass(frozen=True)
class Segment:
    """One subtask of a source demo: its frames [start, stop)."""

    subtask: Subtask
    start: int
    stop: int


def signals(task: Task, source: Source, env=None) -> np.ndarray:
    """(T+1, n) bool: the task's signals (the ends of its subtasks, in order) at each frame of `source`
    and after its last action (the last row repeats the last frame's when read from the frames). Read
    from the recorded frames where the task's signals need no physics (task.resimulate False); else
    re-simulated from its first frame through its recorded actions, and a ValueError when that leaves
    the recorded frames by more than 1 mm (a set from another env)."""
    names = [s.ends for s in task.subtasks if s.ends]
    if not task.resimulate:
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
    """The source's frames cut into task.subtasks: each subtask with an end signal stops at that signal's
    first rising edge after its start (signals), the last one at the source's end. Raises ValueError
    when a signal never rises there (the source does not show that subtask)."""
    n = len(source.actions)
    on = signals(task, source, env) if any(s.ends for s in task.subtasks) else None
    out, start, i = [], 0, 0
    for sub in task.subtasks:
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
    key = (task.name, task.subtasks, source.episode, h.hexdigest())
    if key not in plans:
        plans[key] = cut(task, source)
    return plans[key]


def nearest(task: Task, pool: dict, start) -> int:
    """MimicGen's nearest selection: the episode of the source in `pool` ({episode: Source}) whose start's
    objects lie nearest `start`'s (task.start_distance); ties go to the lowest episode index."""
    return min(pool, key=lambda e: (task.start_distance(task.start_of(pool[e].states[0]), start), e))


def _interp(a, b, s: float) -> tuple[float, float, float]:
    """The planar pose a fraction s (0..1) of the way from a to b (x, y linear; yaw the short way)."""
    dyaw = math.remainder(float(b[2]) - float(a[2]), math.tau)
    return (a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]), float(a[2]) + s * dyaw)


class Replay:
    """One attempt's replay of `plan` (a source's Segments) from `start`: what it found so far and its
    steps (see the module docstring)."""

    def __init__(self, task: Task, source: Source, plan: list[Segment], start):
        self.task, self.source, self.plan, self.start = task, source, plan, start
        self.out_of_reach = False  # a re-expressed waypoint beyond its arm's reach
        self.blocked = False  # a bridge moved the object
        self.seen = dict.fromkeys((s.ends for s in task.subtasks if s.ends), False)  # signals ever on
        self.planned = False  # the plan ran to its end with the episode still going
        self.bridging = None  # the object pose a bridge under way started from

    def segment(self, seg: Segment, now) -> dict:
        """{arm: (waypoints (T, 2) m, velocities (T, 2) m/s, gripper commands (T,) or None)} of `seg`,
        re-expressed for the frames in the observation `now`."""
        task, src = self.task, self.source
        rows = slice(seg.start, seg.stop)
        targets = task.action_to_target(src.states[rows], src.actions[rows])
        first, out = src.states[seg.start], {}
        onto = seg.subtask.onto or (None,) * len(task.arms)
        for arm, frame, to in zip(task.arms, seg.subtask.frames, onto):
            pts, vel, grip = targets[arm]
            if to is None:
                was, now_ = task.frame_pose(frame, first), task.frame_pose(frame, now)
                pts, vel = transform_segment(pts, vel, was, now_)
            else:  # a frame sliding from `frame` onto `to` over the subtask
                a0, a1 = task.frame_pose(frame, first), task.frame_pose(to, first)
                b0, b1 = task.frame_pose(frame, now), task.frame_pose(to, now)
                k = max(len(pts) - 1, 1)
                moved = []
                for t in range(len(pts)):  # frame t in the pose a fraction t / k of the way
                    was, now_ = _interp(a0, a1, t / k), _interp(b0, b1, t / k)
                    moved.append(transform_segment(pts[t : t + 1], vel[t : t + 1], was, now_))
                pts = np.concatenate([m[0] for m in moved]).reshape(-1, 2)
                vel = np.concatenate([m[1] for m in moved]).reshape(-1, 2)
            out[arm] = (pts, vel, None if grip is None else np.asarray(grip, np.float64))
        return out

    def watch(self, obs, env) -> None:
        """Record which of the task's signals are on in the observation `obs` of `env`."""
        if not self.seen:
            return
        for name, on in self.task.signals(obs, env).items():
            if name in self.seen:
                self.seen[name] |= bool(on)

    def steps(self, env):
        """The attempt's actions: a generator primed with next(), then sent each observation (the first,
        then the one after each step) and yielding the next action; it returns when the plan and the
        hold are done. The runner stops sending when the episode ends."""
        task = self.task
        fps = task.env_module.FPS
        obs = yield
        grips = None
        for seg in self.plan:
            segs = self.segment(seg, obs)
            for arm, (pts, _, grip) in segs.items():
                (xlo, xhi), (ylo, yhi) = task.reach[arm]
                inside = (pts[:, 0] >= xlo) & (pts[:, 0] <= xhi) & (pts[:, 1] >= ylo) & (pts[:, 1] <= yhi)
                self.out_of_reach |= not inside.all()
            if grips is None and next(iter(segs.values()))[2] is not None:
                grips = {a: float(segs[a][2][0]) for a in task.arms}  # what each gripper was last told
            if seg.subtask.bridge:
                here = {a: np.asarray(obs[task.arms[a]], np.float64) for a in task.arms}
                first = {a: segs[a][0][0] for a in task.arms}
                dist = max(float(np.hypot(*(first[a] - here[a]))) for a in task.arms)
                n = math.ceil(dist / (task.bridge_speed / fps) - 1e-9) if dist > task.bridge_tol else 0
                self.bridging = task.object_pose(obs)
                for i in range(n):  # linear interpolation, all arms in step
                    wp = {a: here[a] + i / n * (first[a] - here[a]) for a in task.arms}
                    vel = {a: (first[a] - here[a]) * fps / n for a in task.arms}
                    obs = yield task.target_to_action(obs, wp, vel, None if grips is None else dict(grips))
                    self.watch(obs, env)
                self.end_bridge(obs)
            for t in range(seg.stop - seg.start):
                if grips is not None:
                    grips = {a: float(segs[a][2][t]) for a in task.arms}
                obs = yield task.target_to_action(
                    obs, {a: segs[a][0][t] for a in task.arms}, {a: segs[a][1][t] for a in task.arms}, grips
                )
                self.watch(obs, env)
        self.planned = True
        for _ in range(task.hold_steps):  # hold still so a success hold can complete
            here = {a: np.asarray(obs[task.arms[a]], np.float64) for a in task.arms}
            obs = yield task.target_to_action(obs, here, {a: np.zeros(2) for a in task.arms}, grips)
            self.watch(obs, env)

    def end_bridge(self, obs) -> None:
        """Whether the bridge that started at self.bridging moved the object beyond task.bridge_moves."""
        tol = self.task.bridge_moves
        if self.bridging is not None and tol is not None:
            shift = self.task.object_pose(obs) - self.bridging
            turned = abs(math.remainder(shift[2], math.tau))
            self.blocked |= math.hypot(shift[0], shift[1]) > tol[0] or turned > tol[1]
        self.bridging = None

    def outcome(self, env, last_obs, episode: dict) -> Outcome:
        """The Outcome of the frames `episode` recorded (last_obs: the observation after its last step)."""
        self.watch(last_obs, env)
        if self.bridging is not None:  # the episode ended during a bridge
            self.end_bridge(last_obs)
        success = bool(self.task.success(env))
        missed = [name for name, on in self.seen.items() if not on]
        if success:
            why = None
        elif self.out_of_reach:
            why = "path_out_of_reach"
        elif self.blocked:
            why = "approach_blocked"
        elif missed:
            why = f"{missed[0]}_missed"
        elif not self.planned:
            why = "out_of_time"
        else:
            why = "finished_off_target"
        return ended(episode | {"success": success}, why, self.start, self.source.episode)


def replay(task: Task, env, start, source: Source, plans: dict | None = None) -> Outcome:
    """Replay `source` from `start` in `env`, one attempt: its Outcome (the frames executed, as
    datagen.task.rollout records them; reason None on the env's success, else why not). plans: the
    caller's cache of cut sources (plan_of)."""
    try:
        plan = plan_of(task, source, plans)
    except ValueError:
        return Outcome("source_not_split", None, start, source.episode)
    run = Replay(task, source, plan, start)
    obs = task.place(env, start)
    gen = run.steps(env)
    next(gen)
    states, actions, succ = [], [], []
    while True:
        try:
            a = gen.send(obs)
        except StopIteration:
            break
        states.append(obs)
        actions.append(a)
        obs, _, done, info = env.step(a)
        succ.append(bool(info["success"]))
        if done:
            break
    return run.outcome(env, obs, recorded(task.env_module, states, actions, succ, False))
