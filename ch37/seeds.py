"""The seeding rule: demos, augmentation draws and evaluation starts never share an env seed.

Env seeds are carved into disjoint blocks for any --seed >= 0:
env_seed(seed, purpose, i) = (seed * len(PURPOSES) + PURPOSES[purpose]) * SEED_BLOCK + i.
So runs at --seed 0, 1, 2 are independent draws, and no evaluation start is ever a demo start.
"""

from __future__ import annotations

PURPOSES = {"demo": 0, "aug": 1, "eval": 2}
SEED_BLOCK = 1_000_000  # episodes per (seed, purpose) block


def env_seed(seed: int, purpose: str, i: int) -> int:
    if not (0 <= i < SEED_BLOCK) or seed < 0:
        raise ValueError(f"seed must be >= 0 and index in [0, {SEED_BLOCK}); got seed={seed}, i={i}")
    return (seed * len(PURPOSES) + PURPOSES[purpose]) * SEED_BLOCK + i
