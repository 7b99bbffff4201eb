"""The chapter's BC recipe, taken from scale_data.py's measure region, for commands that train more arms.

    recipe = load(hidden_dim=512, batch_size=128, lr=1e-3, seed=0, device="cpu")
    pols, fits = recipe.train([(states, actions), ...], steps)   # arms side by side, equal steps
    rate = recipe.evaluate(pols[0], eval_seeds)                  # success on held-out starts
    lo, hi = recipe.wilson(rate, len(eval_seeds))

The measure region is the one home of the network, the training loop, the rollout and the interval.
load() executes its definitions (imports, functions, classes, and the seeded initial weights) from the
script's own text, so the Scale Lab and the replay comparison train exactly what the lesson trains;
an edit to the region changes them too. Nothing else of the script runs. coverage() does the same
for the emit region's start-coverage count (`cells` and the annulus it divides), interval() for
the region's Wilson interval alone (no torch), the one every tool that reports a rate uses.
"""

from __future__ import annotations

import ast
import functools
from types import SimpleNamespace

from ch37 import ROOT

SCRIPT = ROOT / "scale_data.py"


def _region_nodes(tree: ast.Module, lines: list[str], region: str) -> list[ast.stmt]:
    """The statements of `tree` that sit inside the markers of `region`."""
    start = next(i for i, line in enumerate(lines, 1) if line.startswith(f"# --- region: {region} ---"))
    end = next(i for i, line in enumerate(lines, 1) if i > start and line.startswith("# --- endregion ---"))
    return [node for node in tree.body if start < node.lineno < end]


def _run(region: str, wanted, ns: dict, names: tuple) -> SimpleNamespace:
    """Execute the statements of `region` that `wanted` picks, in `ns`; return `names` from it."""
    text = SCRIPT.read_text()
    nodes = [n for n in _region_nodes(ast.parse(text), text.splitlines(), region) if wanted(n)]
    exec(compile(ast.Module(nodes, []), str(SCRIPT), "exec"), ns)
    missing = [n for n in names if n not in ns]
    if missing:
        raise RuntimeError(f"scale_data.py's {region} region no longer defines {missing}")
    return SimpleNamespace(**{n: ns[n] for n in names})


def _wanted(node: ast.stmt) -> bool:
    """Definitions, imports, and the two statements that make the initial weights."""
    if isinstance(node, (ast.Import, ast.ImportFrom, ast.FunctionDef, ast.ClassDef)):
        return True
    if isinstance(node, ast.Assign):
        return [getattr(t, "id", None) for t in node.targets] == ["init_weights"]
    return isinstance(node, ast.Expr) and ast.unparse(node).startswith("torch.manual_seed(")


def load(*, hidden_dim: int, batch_size: int, lr: float, seed: int, device: str = "cpu", workers: int = 1):
    """The measure region's mlp, BCPolicy, train, evaluate and wilson, bound to these settings.

    `seed` seeds the initial weights and every arm's batch order, as --seed does in the chapter;
    `workers` are the evaluation's physics processes (1: in this process)."""
    import math

    import numpy as np
    import torch

    import pusht_env
    from ch37.demos import progress

    args = SimpleNamespace(
        hidden_dim=hidden_dim, batch_size=batch_size, lr=lr, seed=seed, workers=workers, smoke=True
    )  # smoke=True only silences the progress bars
    ns = {"args": args, "device": torch.device(device), "torch": torch, "np": np, "math": math,
          "pusht_env": pusht_env, "progress": progress, "__name__": "ch37_recipe"}  # fmt: skip
    return _run("measure", _wanted, ns, ("mlp", "BCPolicy", "train", "evaluate", "wilson", "init_weights"))


@functools.cache
def interval():
    """The measure region's `wilson(p_hat, n)`: 95% Wilson interval [lo, hi] of a success rate p_hat
    measured over n episodes. Only that function is executed, so this needs no torch."""
    import math

    def wanted(node):
        return isinstance(node, ast.FunctionDef) and node.name == "wilson"

    return _run("measure", wanted, {"math": math}, ("wilson",)).wilson


@functools.cache
def coverage():
    """The emit region's `cells(starts)` -> (set of (ring, sector), count outside), and its annulus:
    RINGS, SECTORS, R_MIN, R_MAX."""
    import numpy as np

    import pusht_env

    names = ("RINGS", "SECTORS", "R_MIN", "R_MAX", "cells")

    def wanted(node):
        if isinstance(node, ast.FunctionDef):
            return node.name in names
        if isinstance(node, ast.Assign) and len(node.targets) == 1:
            t = node.targets[0]
            ids = [e.id for e in t.elts] if isinstance(t, ast.Tuple) else [getattr(t, "id", None)]
            return all(i in names for i in ids)
        return False

    return _run("emit", wanted, {"np": np, "pusht_env": pusht_env}, names)
