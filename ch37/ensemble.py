"""Several independent MLPs held as one module, so the arms of a training budget run side by side.

The arms of a budget take the same number of steps, so their forward and backward passes can share
one batched matmul (torch.baddbmm over a leading arm axis) instead of one small matmul per arm. This
is PyTorch's model-ensembling pattern (as torch.func.stack_module_state + vmap, written out as one
module): arm e owns slice e of every weight, sees only its own batch, and its loss term is the only
one that depends on its weights, so summing the arms' losses leaves each arm exactly its own
gradient. Adam is elementwise, so one optimizer over the stacked weights is one Adam per arm.
tests/test_ensemble.py checks that an arm trained in the stack ends with the weights it gets alone.

    stack = MLPStack([net.state_dict()] * 2)      # two copies of a Linear/ReLU Sequential
    pred = stack(x)                               # x (E, B, in) -> (E, B, out)
    stack.load_into(net, e)                       # arm e's trained weights back into a Sequential

    with side_by_side(init, nets, device) as stack:   # what bc_recipe.train uses: all of the above
        ...                                       # a training loop over stack(x); then each net is trained

On the CPU the stack's matrix products run on numpy's OpenBLAS, one single-threaded sgemm per arm, the
arms on threads of their own: the published numbers' kernel path (docs/reproducibility.md). torch's
products go through MKL, whose kernels depend on the CPU's maker; OpenBLAS held to one kernel set
(OPENBLAS_CORETYPE=Haswell: AVX2 and FMA, on every x86-64 CPU since 2013, Intel or AMD) and to one
thread per product computes the same bits on any of them, for any thread count (OpenBLAS's own threads
split a product by rows and columns, and a split moves which elements take its edge kernels).
"""

from __future__ import annotations

import contextlib
import ctypes
import re
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch


def openblas(name: str):
    """numpy's OpenBLAS call `name` (get_corename, set_num_threads) as a ctypes function, whichever prefix
    and suffix the build gives its symbols (the wheels' 64-bit build: scipy_openblas_NAME64_), or None
    where numpy has no OpenBLAS loaded in this process (macOS's Accelerate, another BLAS, not Linux)."""
    maps = Path("/proc/self/maps")
    libs = (
        {m.group(0) for m in re.finditer(r"/\S*openblas\S*\.so\S*", maps.read_text())}
        if maps.exists()
        else ()
    )
    for lib in map(ctypes.CDLL, sorted(libs)):
        for symbol in (f"scipy_openblas_{name}64_", f"scipy_openblas_{name}", f"openblas_{name}"):
            if hasattr(lib, symbol):
                return getattr(lib, symbol)
    return None


def blas_core() -> str:
    """The kernel set numpy's OpenBLAS runs in this process ("Haswell", "SkylakeX", ...), chosen once as
    it loads (OPENBLAS_CORETYPE, else this CPU); "" where numpy has no OpenBLAS."""
    get = openblas("get_corename")
    if get is None:
        return ""
    get.restype = ctypes.c_char_p
    return get().decode()


def one_blas_thread() -> bool:
    """Hold numpy's OpenBLAS to one thread per product (its own threads would change the bits with their
    number); False where numpy has no OpenBLAS."""
    set_threads = openblas("set_num_threads")
    if set_threads is None:
        return False
    set_threads(1)
    return True


SPLIT_MIN = 1_000_000  # multiply-adds of one arm's product below which a thread's hand-off costs more


def arms_matmul(a: torch.Tensor, b: torch.Tensor, pool: ThreadPoolExecutor | None) -> torch.Tensor:
    """a @ b per arm, (E, m, k) @ (E, k, n) -> (E, m, n), float32 CPU tensors: one numpy (OpenBLAS) sgemm
    per arm, arms 1.. on `pool` while this thread does arm 0. Where a product is too small to pay for a
    thread's hand-off, numpy loops over the arms itself: the same sgemm per arm, the same bits."""
    x, y = a.detach().numpy(), b.detach().numpy()
    if pool is None or x.shape[1] * x.shape[2] * y.shape[2] < SPLIT_MIN:
        return torch.from_numpy(np.matmul(x, y))
    out = np.empty((x.shape[0], x.shape[1], y.shape[2]), np.float32)
    jobs = [pool.submit(np.matmul, x[e], y[e], out=out[e]) for e in range(1, len(x))]
    np.matmul(x[0], y[0], out=out[0])
    for j in jobs:
        j.result()
    return torch.from_numpy(out)


def arms_grads(x, w, gy, pool, need_gx: bool):
    """gy @ w^T (if need_gx) and x^T @ gy per arm, both of an arm in one job, arms 1.. on `pool`: one
    hand-off where two arms_matmul calls took two, the same sgemm per arm and product."""
    xs, ws, gys = x.detach().numpy(), w.detach().numpy(), gy.detach().numpy()
    e_n, b, i = xs.shape
    o = ws.shape[2]
    gx = np.empty((e_n, b, i), np.float32) if need_gx else None
    gw = np.empty((e_n, i, o), np.float32)

    def arm(e):
        if need_gx:
            np.matmul(gys[e], ws[e].T, out=gx[e])
        np.matmul(xs[e].T, gys[e], out=gw[e])

    if pool is None or b * i * o < SPLIT_MIN:  # arms_matmul's own loop over the arms, one product at a time
        gx = arms_matmul(gy, w.transpose(1, 2), None) if need_gx else None
        return gx, arms_matmul(x.transpose(1, 2), gy, None)
    jobs = [pool.submit(arm, e) for e in range(1, e_n)]
    arm(0)
    for j in jobs:
        j.result()
    return (torch.from_numpy(gx) if need_gx else None), torch.from_numpy(gw)


class ArmsLinear(torch.autograd.Function):
    """b + x @ w per arm, and its gradients, through arms_matmul: (E, B, in), (E, in, out), (E, 1, out)."""

    @staticmethod
    def forward(ctx, x, w, b, pool):
        ctx.save_for_backward(x, w)
        ctx.pool = pool
        return arms_matmul(x, w, pool).add_(b)

    @staticmethod
    def backward(ctx, gy):
        x, w = ctx.saved_tensors
        gy = gy.contiguous()
        gx, gw = arms_grads(x, w, gy, ctx.pool, ctx.needs_input_grad[0])  # (E, B, in), (E, in, out)
        return gx, gw, gy.sum(1, keepdim=True), None


class MLPStack(torch.nn.Module):
    """E copies of a Sequential of Linear layers with ReLU between them, weights stacked on dim 0."""

    def __init__(self, states: list[dict]) -> None:
        super().__init__()
        names = sorted({k.rsplit(".", 1)[0] for k in states[0]}, key=int)  # Linear layers' indices
        self.layers = names
        # weight (E, in, out): transposed once so the forward is x @ W, the layout baddbmm wants
        weights = [torch.stack([s[f"{n}.weight"].t() for s in states]).contiguous() for n in names]
        biases = [torch.stack([s[f"{n}.bias"] for s in states]).unsqueeze(1) for n in names]  # (E, 1, out)
        self.weights = torch.nn.ParameterList(map(torch.nn.Parameter, weights))
        self.biases = torch.nn.ParameterList(map(torch.nn.Parameter, biases))
        self.blas, self.pool = None, None  # numpy's OpenBLAS found, the arms' threads: at the first forward
        self.threads = torch.get_num_threads()  # the threads its arms may take, as the stack is built

    def on_numpy(self) -> bool:
        """Whether the products run on numpy's OpenBLAS, the arms on threads: float32 weights on the CPU
        and a numpy with OpenBLAS (asked once). The caller may then leave torch's own ops one thread."""
        if self.blas is None:
            self.blas = one_blas_thread()
        w = self.weights[0]
        return self.blas and w.device.type == "cpu" and w.dtype == torch.float32

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # (E, B, in) -> (E, B, out)
        numpy_path = self.on_numpy()
        if numpy_path and self.pool is None and min(len(x), self.threads) > 1:  # threads for arms 1..
            self.pool = ThreadPoolExecutor(min(len(x), self.threads) - 1)
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            x = ArmsLinear.apply(x, w, b, self.pool) if numpy_path else torch.baddbmm(b, x, w)  # b + x @ w
            if i < last:
                x = x.relu()
        return x

    @torch.no_grad()
    def load_into(self, net: torch.nn.Sequential, e: int) -> torch.nn.Sequential:
        """Copy arm e's weights into `net` (the Sequential the stack was built from)."""
        state = {}
        for n, w, b in zip(self.layers, self.weights, self.biases):
            state[f"{n}.weight"] = w[e].t().contiguous()
            state[f"{n}.bias"] = b[e, 0].clone()
        net.load_state_dict(state)
        return net


@contextlib.contextmanager
def stacked(init: dict, arms: int, device="cpu"):
    """`arms` copies of the state dict `init` as one MLPStack on `device`, for one training loop: yields the
    stack. While its products run on numpy's OpenBLAS (the published kernel path, its arms on threads of
    their own), torch's own ops, too small here to split, get one thread; torch's thread count is put back
    on leaving, whatever happens."""
    stack = MLPStack([init] * arms).to(device)  # arm e = slice e of every weight
    threads = torch.get_num_threads()
    if stack.on_numpy():
        torch.set_num_threads(1)
    try:
        yield stack
    finally:
        torch.set_num_threads(threads)


@contextlib.contextmanager
def side_by_side(init: dict, nets: list[torch.nn.Sequential], device="cpu"):
    """The arms `nets` (Sequentials shaped as the state dict `init`) as one MLPStack on `device`, every arm
    starting from `init`, for one training loop (stacked): yields the stack; on leaving the block, each
    arm's trained weights are in its net."""
    with stacked(init, len(nets), device) as stack:
        yield stack
    for e, net in enumerate(nets):
        stack.load_into(net, e)


class BatchOrder:
    """Minibatch indices for a set of n rows: one shuffle per pass, read as a continuous stream, so
    every batch holds exactly `batch_size` rows (a pass that ends mid-batch continues into the next
    shuffle). Two orders built with the same seed and n give the same batches."""

    def __init__(self, n: int, batch_size: int, seed: int) -> None:
        self.n, self.batch_size = n, batch_size
        self.gen = torch.Generator().manual_seed(seed)
        self.buf = torch.empty(0, dtype=torch.long)

    def next(self) -> torch.Tensor:
        while len(self.buf) < self.batch_size:
            self.buf = torch.cat([self.buf, torch.randperm(self.n, generator=self.gen)])
        idx, self.buf = self.buf[: self.batch_size], self.buf[self.batch_size :]
        return idx
