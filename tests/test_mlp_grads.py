"""mse_grads gives exactly the gradients autograd gives, and refuses what it cannot differentiate."""

import pytest
import torch

from ch37.mlp_grads import mse_grads


def mlp(widths, seed=0):
    torch.manual_seed(seed)
    layers = []
    for i, (a, b) in enumerate(zip(widths[:-1], widths[1:])):
        layers += [torch.nn.Linear(a, b)] + ([torch.nn.ReLU()] if i < len(widths) - 2 else [])
    return torch.nn.Sequential(*layers)


def autograd_grads(net, x, y):
    net.zero_grad(set_to_none=True)
    torch.nn.functional.mse_loss(net(x), y).backward()
    return [p.grad.clone() for p in net.parameters()]


@pytest.mark.parametrize(
    "widths,batch",
    [
        ((10, 512, 512, 2), 128),
        ((10, 512, 512, 2), 34),
        ((10, 64, 64, 2), 64),
        ((10, 32, 6), 16),
        ((3, 8, 8, 8, 4), 5),
    ],
)
def test_same_bits_as_autograd(widths, batch):
    net = mlp(widths)
    g = torch.Generator().manual_seed(1)
    x, y = (
        torch.rand(batch, widths[0], generator=g) * 2 - 1,
        torch.rand(batch, widths[-1], generator=g) * 2 - 1,
    )
    ref = autograd_grads(net, x, y)
    got = mse_grads(net, x, y)
    assert [t.shape for t in got] == [t.shape for t in ref]
    assert all(torch.equal(a, b) for a, b in zip(got, ref))
    assert any(t.abs().sum() > 0 for t in got) and all(torch.isfinite(t).all() for t in got)


def test_same_training_trajectory_as_autograd():
    """A few Adam steps both ways end at identical weights (the chapter's metrics depend on it)."""
    nets = [mlp((10, 64, 64, 2)), mlp((10, 64, 64, 2))]
    opts = [torch.optim.Adam(n.parameters(), lr=1e-3) for n in nets]
    g = torch.Generator().manual_seed(2)
    for _ in range(20):
        x, y = torch.rand(32, 10, generator=g), torch.rand(32, 2, generator=g)
        opts[0].zero_grad(set_to_none=True)
        torch.nn.functional.mse_loss(nets[0](x), y).backward()
        opts[0].step()
        for p, gr in zip(nets[1].parameters(), mse_grads(nets[1], x, y)):
            p.grad = gr
        opts[1].step()
    assert all(torch.equal(a, b) for a, b in zip(nets[0].parameters(), nets[1].parameters()))


def test_a_wrong_gradient_would_be_caught():
    """The comparison above can fail: a gradient off by one ulp-scale change is not equal."""
    net = mlp((10, 16, 2))
    x, y = torch.rand(8, 10), torch.rand(8, 2)
    got = mse_grads(net, x, y)
    got[0] = got[0] * (1 + 1e-6)
    assert not all(torch.equal(a, b) for a, b in zip(got, autograd_grads(net, x, y)))


@pytest.mark.parametrize("layer", [torch.nn.Tanh(), torch.nn.Linear(8, 8, bias=False), torch.nn.Dropout(0.1)])
def test_refuses_other_layers(layer):
    net = torch.nn.Sequential(torch.nn.Linear(4, 8), layer, torch.nn.Linear(8, 2))
    with pytest.raises(TypeError, match="loss.backward"):
        mse_grads(net, torch.rand(3, 4), torch.rand(3, 2))
