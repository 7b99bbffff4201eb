"""Scripted experts for the two chapter embodiments (PushT and the ALOHA cube handoff).

Each expert is a policy object with ``reset()`` and ``act(obs) -> float32 action``. Optional
Gaussian action noise is drawn from a generator seeded by the caller, so a noisy demo is
bit-for-bit reproducible for a given seed.
"""
from __future__ import annotations

import numpy as np

# --- PushT expert (section owned by the PushT work) ---

# --- ALOHA expert (section owned by the ALOHA work) ---
