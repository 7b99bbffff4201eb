"""The seeding rule: demos, augmentation draws and evaluation starts never share an env seed.

Env seeds are carved into disjoint blocks for any --seed >= 0:
env_seed(seed, purpose, i) = (seed * len(PURPOSES) + PURPOSES[purpose]) * SEED_BLOCK + i.
So runs at --seed 0, 1, 2 are independent draws, and no evaluation start is ever a demo start.
"""

from __future__ import annotations

PURPOSES = {"demo": 0, "aug": 1, "eval": 2}
SEED_BLOCK = 1_000_000  # episodes per (seed, purpose) block
# the largest --seed whose every env seed fits in a signed 64-bit integer (numpy, torch and the
# LeRobot tables store seeds and indices as int64)
MAX_SEED = (2**63 // SEED_BLOCK) // len(PURPOSES) - 1


def env_seed(seed: int, purpose: str, i: int) -> int:
    if not (0 <= i < SEED_BLOCK) or not (0 <= seed <= MAX_SEED):
        raise ValueError(
            f"seed must be in [0, {MAX_SEED}] and index in [0, {SEED_BLOCK}); got seed={seed}, i={i}"
        )
    return (seed * len(PURPOSES) + PURPOSES[purpose]) * SEED_BLOCK + i
