"""The chapter's behaviour-cloning recipe: the one home of the network, the training loop, the rollout
and the numbers a result is read with. scale_data.py's measure region, the Scale Lab and the tools
all import it, so they train and score exactly what the lesson does.

    init = init_weights(hidden_dim, seed)                   # every arm starts from these
    pols, fits = train([(states, actions), ...], steps, init, batch_size=128, lr=1e-3, seed=0)
    rate = evaluate(pols[0], eval_seeds)                    # success on held-out PushT starts
    lo, hi = wilson(rate, len(eval_seeds))                  # its 95% interval
    covered, outside = cells(block_xy)                      # spawn-annulus cells a set of starts covers

Shapes: a state is PushT's observation (10 numbers, see pusht_env.py), an action its pusher
velocity (2 numbers, m/s); the ALOHA handoff's 6-D actions through init_weights(..., act_dim=6) and
evaluate(..., make_env=aloha_env.AlohaCubeEnv). Everything here is a pure function of its arguments.
"""

from __future__ import annotations

import math

import numpy as np
import torch

import pusht_env
from ch37.ensemble import BatchOrder, arm_process_setup, arm_processes, side_by_side
from ch37.parallel import LockstepEnvs, map_jobs, progress


def mlp(
    hidden: int, obs_dim: int = pusht_env.OBS_DIM, act_dim: int = pusht_env.ACT_DIM
) -> torch.nn.Sequential:
    """The BC network: obs_dim -> hidden -> hidden -> act_dim, ReLU (PushT's 10 -> 2 by default)."""
    return torch.nn.Sequential(
        torch.nn.Linear(obs_dim, hidden),
        torch.nn.ReLU(),
        torch.nn.Linear(hidden, hidden),
        torch.nn.ReLU(),
        torch.nn.Linear(hidden, act_dim),
    )


class BCPolicy(torch.nn.Module):
    """The network with min-max normalization of its own training data held in buffers."""

    def __init__(self, states, actions, net):
        super().__init__()
        self.net = net
        for name, x in (("s", states), ("a", actions)):  # min-max ranges of the arm's own data
            lo, hi = torch.as_tensor(x.min(0)), torch.as_tensor(x.max(0))
            self.register_buffer(f"{name}_lo", lo)
            self.register_buffer(f"{name}_span", torch.where(hi - lo > 1e-6, hi - lo, torch.ones_like(lo)))

    def norm_s(self, s):  # -> [-1, 1]
        return 2 * (s - self.s_lo) / self.s_span - 1

    def norm_a(self, a):
        return 2 * (a - self.a_lo) / self.a_span - 1

    def forward(self, s):  # raw state (B, 10) -> raw action (B, 2), m/s
        return (self.net(self.norm_s(s)) + 1) / 2 * self.a_span + self.a_lo


def init_weights(
    hidden: int, seed: int, act_dim: int = pusht_env.ACT_DIM, obs_dim: int = pusht_env.OBS_DIM
) -> dict:
    """The initial weights every arm of a comparison starts from: a pure function of (hidden, seed,
    act_dim, obs_dim); act_dim 6 for the ALOHA handoff."""
    torch.manual_seed(seed)
    return mlp(hidden, obs_dim, act_dim).state_dict()


def train(
    datasets,
    steps: int,
    init: dict,
    *,
    batch_size: int,
    lr: float,
    seed: int,
    device="cpu",
    quiet=True,
    masks=None,
):
    """One BCPolicy per (states, actions) in `datasets`, trained side by side for exactly `steps`
    steps of `batch_size` rows from the weights `init`, every arm with the same batch-order seed.
    Returns the policies and each one's final MSE on its own (normalized) data. `masks`, one (N, act_dim)
    array of 1s (real) and 0s (padding) per dataset, makes the loss and the fit the wrangle region's
    masked MSE: a padded action dimension adds nothing to the loss, hence no gradient. Where the machine
    allows, each arm trains in a forked process of its own (the same bits as side by side in this one)."""
    device = torch.device(device)
    (hidden, obs_dim), act_dim = init["0.weight"].shape, init["4.weight"].shape[0]  # the init's shapes
    pols = [BCPolicy(x, y, mlp(hidden, obs_dim, act_dim)).to(device) for x, y in datasets]
    tensors = [  # normalized once, not per batch
        (p.norm_s(torch.as_tensor(x, device=device)), p.norm_a(torch.as_tensor(y, device=device)))
        for p, (x, y) in zip(pols, datasets)
    ]
    if masks is not None:
        masks = [torch.as_tensor(m, dtype=torch.float32, device=device) for m in masks]
    # The arms train on processes of their own where the machine allows (one an arm, on the CPU under
    # Linux: ch37.ensemble.arm_processes), else all side by side in this one; the same weights either way.
    n = arm_processes(len(pols), device)
    groups = [list(range(j, len(pols), n)) for j in range(n)]  # process j trains arms j, j + n, ...

    def fit(group):  # the BC loop over the arms of `group`; -> their trained weights, as numpy arrays
        orders = [BatchOrder(len(tensors[e][0]), batch_size, seed) for e in group]  # same seed every arm
        bar = progress(None, total=steps, desc="train", quiet=quiet or group[0] > 0)  # one bar for all
        # The group's arms as one network (ch37.ensemble): model(x) maps (arms, B, 10) -> (arms, B, 2), arm e
        # with its own weights; on leaving the block each of their policies holds its trained weights.
        with side_by_side(init, [pols[e].net for e in group], device) as model:
            fused = device.type in ("cpu", "cuda")  # Adam over every weight in one kernel
            opt = torch.optim.Adam(model.parameters(), lr=lr, fused=fused)
            sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=steps)  # lr cosine-decayed to 0
            for _ in range(steps):
                idx = [o.next() for o in orders]
                xb = torch.stack([tensors[e][0][i] for e, i in zip(group, idx)])  # (arms, B, 10)
                yb = torch.stack([tensors[e][1][i] for e, i in zip(group, idx)])  # (arms, B, 2)
                if masks is None:  # each arm's MSE; the sum keeps them apart
                    loss = ((model(xb) - yb) ** 2).mean(dim=(1, 2)).sum()
                else:  # each arm's masked MSE: squared errors on real dimensions over their count
                    mb = torch.stack([masks[e][i] for e, i in zip(group, idx)])
                    loss = (
                        ((model(xb) - yb) ** 2 * mb).sum(dim=(1, 2)) / mb.sum(dim=(1, 2)).clamp(min=1)
                    ).sum()
                opt.zero_grad()
                loss.backward()
                opt.step()
                sched.step()
                bar.update()
        bar.close()
        return [{k: v.cpu().numpy() for k, v in pols[e].net.state_dict().items()} for e in group]

    for group, states in zip(groups, map_jobs(fit, groups, workers=n, setup=arm_process_setup)):
        for e, state in zip(group, states):  # a process's arms, trained there, into this process's policies
            pols[e].net.load_state_dict({k: torch.from_numpy(v) for k, v in state.items()})
    with torch.no_grad():  # fit on each arm's whole training set, a digit-level fingerprint of the run
        if masks is None:
            fits = [torch.nn.functional.mse_loss(p.net(x), y).item() for p, (x, y) in zip(pols, tensors)]
        else:  # the masked MSE the arms trained on
            fits = [
                (((p.net(x) - y) ** 2 * m).sum() / m.sum()).item()
                for p, (x, y), m in zip(pols, tensors, masks)
            ]
    return [p.eval() for p in pols], fits


@torch.no_grad()
def evaluate(pol, seeds, *, workers: int = 1, make_env=pusht_env.PushTEnv) -> float:
    """Success rate of `pol` on starts env.reset(seed) of make_env() (PushT unless told), all episodes
    stepped in lockstep, their physics on `workers` processes (1: in this process); the rate never
    depends on `workers`."""
    device = next(pol.buffers()).device
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a (N, 10) batch needs no second thread; leave the cores to the physics workers
    with LockstepEnvs(make_env, seeds, workers=workers) as envs:
        obs = envs.reset()  # (N, 10)
        live, success = np.ones(len(seeds), bool), np.zeros(len(seeds), bool)
        while live.any():
            idx = np.flatnonzero(live)
            act = pol(torch.as_tensor(obs[idx], device=device)).cpu().numpy()  # one call for every live env
            obs[idx], done, success[idx] = envs.step(idx, act)
            live[idx] = ~done
    torch.set_num_threads(threads)
    return float(success.mean())


def wilson(p_hat: float, n: int, z: float = 1.96) -> list[float]:  # 95% interval of a rate over n episodes
    centre = (p_hat + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p_hat * (1 - p_hat) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return [max(0.0, centre - half), min(1.0, centre + half)]


# Coverage: the spawn annulus split into rings by radius and sectors by angle.
RINGS, SECTORS = 3, 12
R_MIN, R_MAX = pusht_env.SPAWN_R_MIN, pusht_env.SPAWN_R_MAX  # m, the spawn annulus
ANNULUS = (R_MIN, R_MAX, RINGS, SECTORS)


def cells(starts) -> tuple[set, int]:  # (N, 2) block xy -> {(ring, sector)} inside, and the count outside
    r, th = np.hypot(starts[:, 0], starts[:, 1]), np.arctan2(starts[:, 1], starts[:, 0]) % (2 * np.pi)
    inside = (r >= R_MIN) & (r <= R_MAX)
    ring = np.minimum(((r - R_MIN) / (R_MAX - R_MIN) * RINGS).astype(int), RINGS - 1)
    sector = np.minimum((th / (2 * np.pi) * SECTORS).astype(int), SECTORS - 1)
    return {(int(i), int(j)) for i, j, ok in zip(ring, sector, inside) if ok}, int((~inside).sum())
