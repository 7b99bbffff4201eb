"""The measure region trains the two data arms of a budget side by side in one MLPStack. That must be
a speed trick only: an arm trained in the stack ends with the weights it gets when trained alone."""

import pytest
import torch

from ch37.ensemble import BatchOrder, MLPStack
from ch37.process import has_avx2_fma


def mlp(hidden=32):
    return torch.nn.Sequential(
        torch.nn.Linear(10, hidden),
        torch.nn.ReLU(),
        torch.nn.Linear(hidden, hidden),
        torch.nn.ReLU(),
        torch.nn.Linear(hidden, 2),
    )


def fit(datasets, init, steps=40, batch=16, seed=3):
    """The region's loop, on `datasets` [(x, y)], all arms side by side; returns one trained net per arm."""
    model = MLPStack([init] * len(datasets))
    orders = [BatchOrder(len(x), batch, seed) for x, _ in datasets]
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=steps)
    for _ in range(steps):
        idx = [o.next() for o in orders]
        xb = torch.stack([x[i] for (x, _), i in zip(datasets, idx)])
        yb = torch.stack([y[i] for (_, y), i in zip(datasets, idx)])
        loss = ((model(xb) - yb) ** 2).mean(dim=(1, 2)).sum()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
    return [model.load_into(mlp(), e) for e in range(len(datasets))]


def data(n, seed):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n, 10, generator=g) * 2 - 1, torch.rand(n, 2, generator=g) * 2 - 1


def test_stack_forward_is_each_net_forward():
    torch.manual_seed(0)
    nets = [mlp(), mlp()]
    stack = MLPStack([n.state_dict() for n in nets])
    x = torch.randn(2, 5, 10)
    torch.testing.assert_close(stack(x), torch.stack([nets[0](x[0]), nets[1](x[1])]))


def test_round_trip_of_weights():
    torch.manual_seed(1)
    net = mlp()
    back = MLPStack([net.state_dict()] * 3).load_into(mlp(), 2)
    for (k, a), b in zip(net.state_dict().items(), back.state_dict().values()):
        assert torch.equal(a, b), k


@pytest.mark.parametrize("other_n", [37, 100])
def test_an_arm_in_the_stack_trains_as_if_alone(other_n):
    torch.manual_seed(2)
    init = mlp().state_dict()
    mine, other = data(50, 0), data(other_n, 1)
    alone = fit([mine], init)[0]
    together = fit([mine, other], init)
    for (k, a), b in zip(alone.state_dict().items(), together[0].state_dict().values()):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6, msg=k)
    # and the other arm really trained on something else: a coupling bug would not hide behind equality
    assert not torch.allclose(together[0][0].weight, together[1][0].weight)


@pytest.mark.parametrize("lanes", [2, 3])
def test_the_arms_threads_change_no_bit(monkeypatch, lanes):
    """Three arms' passes spread over `lanes` threads (ch37.ensemble.ArmsMLP; with 2, one thread takes
    two arms) or all on one thread: the same weights, bit for bit, and the same input gradient, where the
    products run on numpy's OpenBLAS."""
    from ch37 import ensemble

    torch.manual_seed(2)
    init = mlp().state_dict()
    sets = [data(50, 0), data(37, 1), data(64, 2)]
    threads = torch.get_num_threads()
    torch.set_num_threads(lanes)  # the stack takes its arms' threads from torch's count as it is built
    try:
        got = {}
        for split_min in (0, 10**12):  # every pass on the arms' threads; none
            monkeypatch.setattr(ensemble, "SPLIT_MIN", split_min)
            x = torch.stack([x[:16] for x, _ in sets]).requires_grad_()
            stack = MLPStack([init] * 3)
            stack(x).square().sum().backward()
            got[split_min] = ([t.detach() for t in fit(sets, init)[0].state_dict().values()], x.grad)
            if not stack.on_numpy():
                pytest.skip("the products run on torch here: no arms' threads")
            assert split_min or stack.pool is not None
    finally:
        torch.set_num_threads(threads)
    (w0, g0), (w1, g1) = got.values()
    assert all(torch.equal(a, b) for a, b in zip(w0, w1)) and torch.equal(g0, g1)


def test_a_coupled_loss_would_be_caught():
    """The mean over arms (instead of the sum) halves each arm's gradient; Adam mostly hides a scale,
    so couple the arms for real: a loss on the arms' average prediction. The check must see it."""
    torch.manual_seed(2)
    init = mlp().state_dict()
    mine, other = data(50, 0), data(37, 1)
    alone = fit([mine], init)[0]
    model = MLPStack([init, init])
    opt = torch.optim.Adam(model.parameters(), lr=1e-2)
    orders = [BatchOrder(50, 16, 3), BatchOrder(37, 16, 3)]
    for _ in range(40):
        idx = [o.next() for o in orders]
        xb = torch.stack([mine[0][idx[0]], other[0][idx[1]]])
        yb = torch.stack([mine[1][idx[0]], other[1][idx[1]]])
        loss = ((model(xb).mean(0) - yb[0]) ** 2).mean()  # arms coupled through the mean
        opt.zero_grad()
        loss.backward()
        opt.step()
    coupled = model.load_into(mlp(), 0)
    assert not torch.allclose(alone[0].weight, coupled[0].weight, rtol=1e-5, atol=1e-6)


def test_batch_order_streams_full_batches_and_repeats_by_seed():
    a, b = BatchOrder(10, 4, 7), BatchOrder(10, 4, 7)
    batches = [a.next() for _ in range(5)]  # 20 rows = exactly two passes over 10
    assert all(len(x) == 4 for x in batches)
    rows = torch.cat(batches)
    assert sorted(rows[:10].tolist()) == list(range(10)) and sorted(rows[10:].tolist()) == list(range(10))
    assert all(torch.equal(x, b.next()) for x in batches)
    assert not torch.equal(torch.cat([BatchOrder(10, 4, 8).next() for _ in range(5)]), rows)
    small = BatchOrder(3, 8, 0).next()  # fewer rows than a batch: still a full batch
    assert len(small) == 8 and set(small.tolist()) == {0, 1, 2}


# Issue 47: the stack's products on numpy's OpenBLAS (Haswell's kernels, one thread per product) give
# the same weights whatever the thread counts, torch's vector kernels or MKL's branch; other OpenBLAS
# kernels give others (so the check can fail).
TRAIN_BITS = r"""
import hashlib, sys
import numpy as np, torch
import bc_recipe as bc
torch.set_num_threads(int(sys.argv[1]))
rng = np.random.default_rng(0)
data = [(rng.normal(size=(n, 10)), rng.normal(size=(n, 2))) for n in (60, 300)]
data = [(x.astype(np.float32), y.astype(np.float32)) for x, y in data]
pols, _ = bc.train(data, 30, bc.init_weights(512, 0), batch_size=128, lr=1e-3, seed=0)
weights = [t.numpy().tobytes() for p in pols for t in p.net.state_dict().values()]
print(hashlib.sha256(b"".join(weights)).hexdigest())
"""


def trained_bits(threads: int, **env: str) -> str:
    import os
    import subprocess
    import sys

    from conftest import ROOT

    base = {k: v for k, v in os.environ.items() if k not in ("MKL_CBWR", "ATEN_CPU_CAPABILITY")}
    p = subprocess.run(
        [sys.executable, "-c", TRAIN_BITS, str(threads)],
        cwd=ROOT,
        env=base | {"OPENBLAS_CORETYPE": "Haswell"} | env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.returncode == 0, p.stderr
    return p.stdout.strip()


@pytest.mark.skipif(
    not has_avx2_fma(), reason="the published kernel path needs an x86-64 CPU with AVX2 and FMA"
)
def test_the_training_bits_hold_across_threads_vector_kernels_and_mkl_branches():
    held = trained_bits(2, MKL_CBWR="COMPATIBLE")
    assert trained_bits(1) == held  # one thread: no arm threads, MKL's own branch
    assert trained_bits(4, MKL_CBWR="AVX2") == held  # more threads than arms
    assert trained_bits(2, ATEN_CPU_CAPABILITY="avx2") == held  # torch's AVX2 vector kernels
    assert trained_bits(2, OPENBLAS_CORETYPE="Sandybridge") != held  # OpenBLAS's AVX kernels: other bits


# Issue 59: bc_recipe.train gives each arm a forked process of its own where it may (arm_processes).
def two_arms_trained(threads: int):
    import hashlib

    import numpy as np

    import bc_recipe as bc

    rng = np.random.default_rng(0)
    data = [
        (rng.normal(size=(n, 10)).astype(np.float32), rng.normal(size=(n, 2)).astype(np.float32))
        for n in (60, 90)
    ]
    saved = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        pols, fits = bc.train(data, 12, bc.init_weights(64, 0), batch_size=32, lr=1e-3, seed=0)
    finally:
        torch.set_num_threads(saved)
    weights = b"".join(t.numpy().tobytes() for p in pols for t in p.net.state_dict().values())
    return hashlib.sha256(weights).hexdigest(), fits


def test_a_process_that_has_used_cuda_keeps_its_arms_at_home(monkeypatch):
    """A cuda run then a cpu run in one process (tools/gpu_check.sh's step 4 on an H200) stopped in the forked
    arm's backward: CUDA's autograd threads do not survive a fork. Once CUDA is initialised, arm_processes
    gives 1 (the arms side by side in this process); before, 2. This machine has no GPU, so the query
    torch.cuda.is_initialized answers both ways here by hand."""
    from ch37.ensemble import arm_processes
    from ch37.parallel import can_fork

    if not can_fork():
        pytest.skip("no fork here: the arms train side by side in this process only")
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        monkeypatch.setattr(torch.cuda, "is_initialized", lambda: False)
        assert arm_processes(2, "cpu") == 2
        monkeypatch.setattr(torch.cuda, "is_initialized", lambda: True)
        assert arm_processes(2, "cpu") == 1
    finally:
        torch.set_num_threads(threads)


def test_arms_in_processes_of_their_own_train_as_side_by_side_in_one():
    from ch37.ensemble import arm_processes
    from ch37.parallel import can_fork

    if not can_fork():
        pytest.skip("no fork here: the arms train side by side in this process only")
    threads = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        assert arm_processes(2, "cpu") == 2 and arm_processes(3, "cpu") == 2 and arm_processes(1, "cpu") == 1
    finally:
        torch.set_num_threads(threads)
    apart, together = two_arms_trained(2), two_arms_trained(1)  # two processes; both arms in this one
    assert apart == together
    assert len(set(apart[1])) == 2  # two arms that really differ: a swapped hand-back would not hide


def test_train_inside_a_worker_keeps_its_arms_at_home():
    """A forked map_jobs worker may have no children of its own (multiprocessing's daemons): there
    arm_processes gives 1, and bc_recipe.train trains its arms side by side in that worker, with the same
    weights, instead of failing."""
    from ch37.ensemble import arm_processes
    from ch37.parallel import can_fork, map_jobs

    if not can_fork():
        pytest.skip("no fork here")

    def job(_):
        torch.set_num_threads(2)  # as many as the arms: a process an arm, were this not a worker
        n = arm_processes(2, "cpu")
        # OpenMP's threads do not survive a fork (a second one would wait for ever): a worker trains on one
        return n, two_arms_trained(1)

    at_home = two_arms_trained(2)
    assert list(map_jobs(job, [0, 1], workers=2)) == [(1, at_home), (1, at_home)]


def test_map_jobs_runs_setup_in_its_forked_workers_only():
    import os

    from ch37.parallel import can_fork, map_jobs

    if not can_fork():
        pytest.skip("no fork here")

    def setup():
        os.environ["CH37_TEST_SETUP"] = str(os.getpid())

    def job(_):
        return os.environ.get("CH37_TEST_SETUP") == str(os.getpid())

    assert list(map_jobs(job, range(4), workers=2, setup=setup)) == [True] * 4
    assert list(map_jobs(job, range(4), workers=1, setup=setup)) == [False] * 4  # in this process: no setup
    assert "CH37_TEST_SETUP" not in os.environ
