"""Reference answer to exercises/ex2_completion_wrangle.py: the task is that file's docstring."""

import numpy as np


def mix_embodiments(pusht_actions, aloha_actions):
    """(N, 2) PushT and (M, 6) ALOHA actions -> (actions (N+M, 6) f32, mask (N+M, 6) f32, id (N+M,) i64)."""
    n, m = len(pusht_actions), len(aloha_actions)
    actions = np.zeros((n + m, 6), np.float32)  # new arrays: the inputs are never written to
    actions[:n, :2] = pusht_actions  # PushT first, real dims on the left, zeros in columns 2..5
    actions[n:] = aloha_actions
    mask = np.zeros((n + m, 6), np.float32)
    mask[:n, :2] = 1.0  # PushT: [1, 1, 0, 0, 0, 0], density 1/3
    mask[n:] = 1.0  # ALOHA: every dim is real
    embodiment_id = np.concatenate([np.zeros(n, np.int64), np.ones(m, np.int64)])
    return actions, mask, embodiment_id
