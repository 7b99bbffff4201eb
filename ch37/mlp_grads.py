"""Exact gradients of the mean-squared error of a Linear/ReLU MLP, without autograd.

scale_data.py trains its behaviour-cloning MLP for about 18,000 small steps (batch 128) on two CPU
cores. At that size autograd's per-op bookkeeping (recording the graph in the forward pass, then
walking it node by node) costs about a tenth of every step (2.28 vs 2.04 ms measured). For a plain
stack of Linear and ReLU layers the backward pass is a dozen tensor ops, written out below. They are
the ops autograd itself runs for these layers, in the same order and orientation, so the gradients
are bit for bit the ones `F.mse_loss(net(x), y).backward()` leaves in `p.grad`
(tests/test_mlp_grads.py checks this). Any other layer type is refused rather than silently mis-
differentiated.

    grads = mse_grads(net, x, y)          # one tensor per net.parameters(), in that order
    for p, g in zip(net.parameters(), grads):
        p.grad = g
    optimizer.step()
"""

from __future__ import annotations

import torch


def mse_grads(net: torch.nn.Sequential, x: torch.Tensor, y: torch.Tensor) -> list[torch.Tensor]:
    """Gradients of `F.mse_loss(net(x), y)` (mean over all elements) with respect to
    `net.parameters()`, in that order. `net` is a Sequential of Linear (with bias) and ReLU."""
    layers = list(net)
    for layer in layers:
        if not (
            isinstance(layer, torch.nn.ReLU)
            or (isinstance(layer, torch.nn.Linear) and layer.bias is not None)
        ):
            raise TypeError(
                f"mse_grads handles Linear (with bias) and ReLU layers, not {layer!r}; use loss.backward()"
            )
    with torch.no_grad():
        acts = [x]  # acts[i] is the input of layers[i]; acts[-1] is the prediction
        for layer in layers:
            h = acts[-1]
            acts.append(
                torch.addmm(layer.bias, h, layer.weight.t())
                if isinstance(layer, torch.nn.Linear)
                else h.relu()
            )
        pred = acts[-1]
        g = (pred - y).mul_(2.0 / pred.numel())  # d mean((pred - y)^2) / d pred, as aten's mse_loss_backward
        grads: list[torch.Tensor] = []  # filled from the last layer back
        for i in range(len(layers) - 1, -1, -1):
            layer = layers[i]
            if isinstance(layer, torch.nn.ReLU):
                g = torch.ops.aten.threshold_backward(
                    g, acts[i + 1], 0
                )  # ReLU's backward: zero where the output is 0
                continue
            grads += [g.sum(0), g.t() @ acts[i]]  # bias (out,), weight (out, in)
            if i > 0:  # the network's own input needs no gradient
                g = g @ layer.weight
    return grads[::-1]
