"""Exercise 2 (code completion): pool a 2-D and a 6-D action array into one padded batch.

Objective
    Write the step that lets one policy train on two robots with different action sizes:
    zero-pad every action to the widest robot (6) and keep an action mask, so a masked loss
    never learns from the padding, plus an embodiment id per row. This is the action side of
    the wrangle region of scale_data.py (and of Open X-Embodiment-style pooling).

What to do
    Implement mix_embodiments below, replacing the NotImplementedError.

    Inputs
        pusht_actions  array (N, 2), any float dtype: PushT pusher velocities
        aloha_actions  array (M, 6), any float dtype: ALOHA two-arm commands
        N or M may be 0.
    Returns a tuple (actions, mask, embodiment_id)
        actions        (N + M, 6) float32. PushT rows first, then ALOHA rows, each in its
                       original order. A PushT row keeps its 2 numbers in columns 0..1 and has
                       zeros in columns 2..5 (pad on the right).
        mask           (N + M, 6) float32. 1.0 where the dimension is real, 0.0 where it is
                       padding. So a PushT row's mask is [1, 1, 0, 0, 0, 0] (density 1/3) and an
                       ALOHA row's mask is all ones.
        embodiment_id  (N + M,) int64. 0 for PushT rows, 1 for ALOHA rows.
    Do not modify the input arrays.

    Hint: np.zeros, np.concatenate and astype are enough; about 6 lines.

How to check (from the repository root, after the README's set-up)
    .venv/bin/python -m pytest exercises/checks.py -k ex2
    (with .venv activated: python -m pytest exercises/checks.py -k ex2)
    (deterministic, under a second; it compares your function with the specification on several
    shapes, including N = 0, M = 0 and N = 1, on float32 and float64 inputs, and on actions that are
    exactly 0 in a real dimension, as an arm at rest gives: the mask says which dimensions a robot
    has, not which values are nonzero)

Estimated time: 15 minutes.
"""

import numpy as np  # noqa: F401  (you will need it)


def mix_embodiments(pusht_actions, aloha_actions):
    """(N, 2) PushT and (M, 6) ALOHA actions -> (actions (N+M, 6) f32, mask (N+M, 6) f32, id (N+M,) i64)."""
    raise NotImplementedError("fill in mix_embodiments (see the module docstring)")
