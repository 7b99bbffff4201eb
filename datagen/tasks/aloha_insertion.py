"""LeRobot's ALOHA insertion (gym-aloha's AlohaInsertion-v0, ACT's sim_insertion) as a data-engine task: the
left arm grasps the socket, the right the peg, and they meet in the air until the peg touches the socket's
pin. gym-aloha's model files on our mujoco (datagen/tasks/aloha_sim.py); everything but its objects as
datagen/tasks/aloha_transfer_cube.py has it (the columns, the arms, the end-effector targets, the IK).

    env        datagen.tasks.aloha_sim.InsertionEnv; its observation: the 14 of observation.state, then the
               peg's pose (7) and the socket's (7)
    start      the peg's and the socket's poses (START_NAMES), drawn as gym-aloha's reset(seed=seed) does
    perturb    the peg's and the socket's (x, y) get Gaussian noise of pos_sigma m each, re-drawn (up to
               TRIES) until inside gym-aloha's ranges; both stay upright
    success    gym-aloha's: InsertionTask.get_reward's top stage (the peg touches the pin)
    expert     datagen.tasks.aloha_sim_expert.InsertionExpert (ACT's InsertionPolicy's waypoints through
               IK, the
               insertion planned from where the parts lie in the hands)
    frames     peg, socket, the world
    subtasks   grasp (the left arm relative to the socket, the right to the peg; it ends when both are
               lifted 2 cm) and insert (both relative to the world: the meeting point is fixed), each
               entered by a bridge at bridge_speed, faster than the source moves, so that a replay fits
               ACT's 400 steps
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from datagen.poses import rotation_of
from datagen.task import GymnasiumEnv, Perturbation, Subtask, register
from datagen.tasks.aloha_sim import PEG_RANGE, SOCKET_RANGE
from datagen.tasks.aloha_sim_expert import InsertionExpert
from datagen.tasks.aloha_transfer_cube import MAX_STEPS, MOTORS, TRIES, AlohaTransferCube, JointIK
from datagen.tasks.aloha_transfer_cube import SPEC as TRANSFER_CUBE_SPEC

__all__ = ["ALOHA_INSERTION", "AlohaInsertion", "SPEC", "START_NAMES"]

START_NAMES = tuple(f"{o}_{n}" for o in ("peg", "socket") for n in ("x", "y", "z", "qw", "qx", "qy", "qz"))
SPEC = replace(  # the transfer-cube's columns, packages, reward and end-effector targets; its own objects
    TRANSFER_CUBE_SPEC,
    fps=50,
    robot_type="aloha",  # the hub sets' own (lerobot/aloha_sim_insertion_*)
    task="Insert the peg into the socket.",
    max_steps=MAX_STEPS,
    env_state_names=START_NAMES,
    obs_names=MOTORS + START_NAMES,
)
OBJECTS = slice(14, 28)
PEG, SOCKET = slice(14, 21), slice(21, 28)
SUBTASKS = (
    Subtask("grasp", ("socket", "peg"), ends="held"),  # each arm grasps its part and lifts it
    Subtask("insert", ("world", "world")),  # the parts meet at a fixed point in the air
)
# m: the peg's and the socket's centres at rest on the table (half their heights); both held LIFT above
# them ends the grasp (gym-aloha's stage 2, both held off the table, flickers with the finger contacts)
REST_Z, LIFT = (0.01, 0.02), 0.02


def _pose(part) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rotation_of(part[3:7]), part[:3]
    return out


class AlohaInsertion(AlohaTransferCube):
    """gym-aloha's insertion for the engine (see the module docstring)."""

    name, title = "aloha_insertion", "ALOHA insertion (gym-aloha's ViperX sim)"
    spec = SPEC
    start_names = START_NAMES
    expert = replace(AlohaTransferCube.expert, cls=InsertionExpert)
    replay = replace(
        AlohaTransferCube.replay,
        action=JointIK("insertion"),
        subtasks=SUBTASKS,
        # m/s. A source takes 361 of ACT's 400 steps, and a replay adds two bridges, each about as long as
        # the farther part moved (into the parts' frames for the grasp, back to the fixed meeting point for
        # the insert); at the source's own top speed (0.10-0.12 m/s) the two cost 10 steps per cm and ran
        # out of time beyond about 4 cm, at this speed 5 per cm (8 cm). They move the arms in the air,
        # which the position servos track at this speed (docs/replay.md: the insertion's time limit)
        bridge_speed=0.2,
        resimulate=False,  # "held" shows in an observation
    )
    scene, objects = "insertion", OBJECTS

    def __init__(self, subtasks: tuple[Subtask, ...] | None = None):  # None: SUBTASKS
        if subtasks is not None:
            self.replay = replace(self.replay, subtasks=subtasks)

    def make_env(self, share=None):
        from datagen.tasks.aloha_sim import InsertionEnv

        env = InsertionEnv(MAX_STEPS, share=None if share is None else share.env)
        return GymnasiumEnv(env, lambda obs: np.asarray(obs, np.float32))

    def perturb(self, first_state, rng, how: Perturbation):
        start = list(self.start_of(first_state))
        for at, box in ((0, PEG_RANGE), (7, SOCKET_RANGE)):
            for _ in range(TRIES):
                xy = np.array(start[at : at + 2]) + rng.normal(0, how.pos_sigma, 2)
                if all(lo <= v <= hi for v, (lo, hi) in zip(xy, box)):  # float32: aug.start re-runs it
                    start[at : at + 2] = [float(np.float32(v)) for v in xy]
                    break
            else:
                return None
        return tuple(start)

    def object_pose(self, state) -> np.ndarray:
        return _pose(np.asarray(state[PEG], np.float64))

    def frame_pose(self, frame: str, state) -> np.ndarray:
        if frame == "world":
            return np.eye(4)
        return _pose(np.asarray(state[PEG if frame == "peg" else SOCKET], np.float64))

    def signals(self, obs, env) -> dict[str, bool]:
        lifted = obs[PEG][2] > REST_Z[0] + LIFT and obs[SOCKET][2] > REST_Z[1] + LIFT
        return {"held": bool(lifted)}


ALOHA_INSERTION = register(AlohaInsertion())
