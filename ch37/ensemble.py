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
arms on threads of their own: the published numbers' kernel path (docs/reproducibility.md). Where the
machine allows, bc_recipe.train goes one step further and gives each arm a forked process of its own
(arm_processes, arm_process_setup): an arm's whole loop, its Adam and its batches included, then runs
beside the other's, with no lock between them; each process holds a stack of one arm, so the weights are
the same bits. torch's products go through MKL, whose kernels depend on the CPU's maker; OpenBLAS held to
one kernel set (OPENBLAS_CORETYPE=Haswell: AVX2 and FMA, on every x86-64 CPU since 2013, Intel or AMD)
and to one thread per product computes the same bits on any of them, for any thread count (OpenBLAS's
own threads split a product by rows and columns, and a split moves which elements take its edge
kernels).
"""

from __future__ import annotations

import contextlib
import ctypes
import importlib
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


SPLIT_MIN = 1_000_000  # multiply-adds of one arm's pass below which a thread's hand-off costs more


def on_arms(arm, arms: int, pool: ThreadPoolExecutor | None, lanes: int) -> None:
    """arm(e) for every arm e on `lanes` threads, lane j taking arms j, j + lanes, ...: lanes 1.. on
    `pool`, lane 0 on this thread (all on this thread if no pool). The work of one arm never touches
    another's slices, so neither the order nor the lane changes a bit."""
    lanes = min(lanes, arms) if pool is not None else 1

    def lane(j):
        for e in range(j, arms, lanes):
            arm(e)

    jobs = [pool.submit(lane, j) for j in range(1, lanes)]
    lane(0)
    for j in jobs:
        j.result()


class ArmsMLP(torch.autograd.Function):
    """The stack's whole forward and backward, the arms' passes spread over `lanes` threads (on_arms): one
    hand-off per pass where one per layer left each layer's bias, ReLU and small products on one thread.

    Per arm and layer i (weights W_i (in, out), biases b_i (1, out), on slices of the stacked tensors):
        forward   z_i = h_{i-1} @ W_i + b_i;  h_i = relu(z_i) but for the last layer  (h_{-1} = x)
        backward  dW_i = h_{i-1}^T @ g_i;  g_{i-1} = relu'(h_{i-1}) * (g_i @ W_i^T);  db_i = sum of g_i's rows
    Every product is one numpy (OpenBLAS) sgemm of one arm's matrices, the bias, ReLU and its gradient
    torch's own kernels (an elementwise op computes an element alike in any slice), the bias gradient one
    sum over the stacked rows: the arithmetic, op for op, of torch's autograd over Linear and ReLU layers
    whose products are these sgemms."""

    @staticmethod
    def forward(ctx, x, pool, lanes, *params):
        n = len(params) // 2
        ws = [w.detach().numpy() for w in params[:n]]  # (E, in, out) each
        bs = [b.detach() for b in params[n:]]  # (E, 1, out) each
        xs = x.detach().numpy()  # (E, B, in)
        arms, rows = xs.shape[:2]
        hs = [np.empty((arms, rows, w.shape[2]), np.float32) for w in ws]  # each layer's output, (E, B, out)

        def arm(e):
            h = xs[e]
            for i in range(n):
                np.matmul(h, ws[i][e], out=hs[i][e])
                z = torch.from_numpy(hs[i][e]).add_(bs[i][e])
                if i < n - 1:
                    z.relu_()  # the hidden layer's output, kept for the backward
                h = hs[i][e]

        ctx.pool = pool if rows * sum(w[0].size for w in ws) >= SPLIT_MIN else None  # worth a hand-off
        ctx.lanes = lanes
        on_arms(arm, arms, ctx.pool, lanes)
        ctx.save_for_backward(x, *params[:n], *map(torch.from_numpy, hs[:-1]))
        return torch.from_numpy(hs[-1])

    @staticmethod
    def backward(ctx, gout):
        x, *saved = ctx.saved_tensors
        n = (len(saved) + 1) // 2
        ws = [w.detach().numpy() for w in saved[:n]]
        ins = [x.detach().numpy()] + [h.numpy() for h in saved[n:]]  # each layer's input, (E, B, in)
        arms, rows = ins[0].shape[:2]
        gs = [np.empty_like(h) for h in ins[1:]] + [gout.contiguous().numpy()]  # dloss/dz_i, (E, B, out)
        gws = [np.empty_like(w) for w in ws]  # (E, in, out)
        need_gx = ctx.needs_input_grad[0]
        gx = np.empty_like(ins[0]) if need_gx else None

        def arm(e):
            for i in reversed(range(n)):
                g = gs[i][e]
                np.matmul(ins[i][e].T, g, out=gws[i][e])
                if i > 0:  # through the ReLU below: the gradient where its output was positive
                    gh = torch.from_numpy(np.matmul(g, ws[i][e].T))
                    h = torch.from_numpy(ins[i][e])
                    torch.ops.aten.threshold_backward.grad_input(
                        gh, h, 0, grad_input=torch.from_numpy(gs[i - 1][e])
                    )
                elif need_gx:
                    np.matmul(g, ws[0][e].T, out=gx[e])

        on_arms(arm, arms, ctx.pool, ctx.lanes)
        gbs = [torch.from_numpy(g).sum(1, keepdim=True) for g in gs]  # (E, 1, out)
        return (torch.from_numpy(gx) if need_gx else None), None, None, *map(torch.from_numpy, gws), *gbs


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
        if self.on_numpy():
            lanes = min(len(x), self.threads)  # the arms' threads, this one included
            if self.pool is None and lanes > 1:
                self.pool = ThreadPoolExecutor(lanes - 1)
            return ArmsMLP.apply(x, self.pool, lanes, *self.weights, *self.biases)
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            x = torch.baddbmm(b, x, w)  # b + x @ w
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


def arm_processes(arms: int, device) -> int:
    """How many processes bc_recipe.train spreads `arms` over: one an arm, up to torch's thread count, on the
    CPU where this process may fork workers (ch37.parallel.can_fork); else 1, every arm side by side in
    this process (the stack's arms on threads). Also 1 once this process has used CUDA: its autograd
    threads do not survive a fork, and a forked arm's backward then stops with "Unable to handle autograd's
    threading in combination with fork-based multiprocessing" (a cuda run, then a cpu one, in one process:
    tools/gpu_check.sh's step 4 on an H200). The weights never depend on it (tests/test_ensemble.py)."""
    from ch37.parallel import can_fork

    forkable = can_fork() and not torch.cuda.is_initialized()
    n = min(arms, torch.get_num_threads()) if torch.device(device).type == "cpu" and forkable else 1
    if n > 1:  # torch's first optimizer imports torch._dynamo (0.9 s): here once, not in every fork
        importlib.import_module("torch._dynamo")
    return max(1, n)


def arm_process_setup() -> None:
    """First call in an arm's training process (arm_processes): one torch thread, the process being the
    arm's core; and glibc's heap held. A step frees its gradients (1 MiB a 512 x 512 weight) and
    allocates them again; glibc's defaults hand that memory back to the kernel each time and fault it in
    again, a fifth of a lone arm's step (perf record, issue 59). A threshold fixed by hand also stops
    glibc from moving it."""
    torch.set_num_threads(1)
    libc = ctypes.CDLL(None)
    if hasattr(libc, "mallopt"):  # glibc; others keep their own heap
        M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's malloc.h
        libc.mallopt(M_MMAP_THRESHOLD, 64 << 20)  # bytes: blocks under 64 MiB from the heap, not mmap
        libc.mallopt(M_TRIM_THRESHOLD, 256 << 20)  # bytes: hand the heap's top back only past 256 MiB free


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
