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
"""

from __future__ import annotations

import torch


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

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # (E, B, in) -> (E, B, out)
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            x = torch.baddbmm(b, x, w)  # b + x @ w, per arm
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
