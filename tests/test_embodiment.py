"""Objective 2, measured (issue 60 #1): python -m tools.embodiment, the masked loss it trains with in
bc_recipe.train, and the kept result (results/embodiment.json) the README and the poster read."""

import json
import math

import numpy as np
import pytest
import torch
from conftest import ROOT, run_script

import bc_recipe as bc

KEPT = ROOT / "results" / "embodiment.json"


def _padded_set(n=96, seed=0):
    """A PushT-like set padded to 6: 2 real action columns, 4 of padding, and its mask."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 12)).astype(np.float32)
    y = np.zeros((n, 6), np.float32)
    y[:, :2] = rng.normal(size=(n, 2))
    mask = np.zeros((n, 6), np.float32)
    mask[:, :2] = 1.0
    return x, y, mask


def test_the_masked_loss_learns_nothing_from_padding():
    """Junk in the padded columns changes no weight under the mask (no loss, so no gradient there), and
    does without it; an all-ones mask trains as the unmasked loss does."""
    x, y, mask = _padded_set()
    junk = y.copy()
    junk[:, 2:] = np.random.default_rng(1).normal(size=(len(y), 4)) * 5
    init = bc.init_weights(16, 0, act_dim=6, obs_dim=12)
    hp = dict(batch_size=32, lr=1e-2, seed=0)
    (clean, dirty), _ = bc.train([(x, y), (x, junk)], 20, init, masks=[mask, mask], **hp)
    for (k, a), b in zip(clean.net.state_dict().items(), dirty.net.state_dict().values()):
        assert torch.equal(a, b), k
    (unmasked,), _ = bc.train([(x, junk)], 20, init, **hp)
    assert not torch.equal(unmasked.net[0].weight, clean.net[0].weight)
    (ones,), (fit_ones,) = bc.train([(x, junk)], 20, init, masks=[np.ones_like(mask)], **hp)
    (plain,), (fit_plain,) = bc.train([(x, junk)], 20, init, **hp)
    torch.testing.assert_close(ones.net[0].weight, plain.net[0].weight)
    assert fit_ones == pytest.approx(fit_plain, rel=1e-5)


def test_the_command_runs_end_to_end_at_tiny_sizes(tmp_path):
    out = tmp_path / "emb"
    p = run_script(
        "-m", "tools.embodiment", "--smoke", "--seeds", "1", "--eval_episodes", "1", "--workers", "1",
        "--out", out,
    )  # fmt: skip
    r = json.loads((out / "embodiment.json").read_text())
    assert r["kind"] == "embodiment" and r["command"].startswith(
        "python -m tools.embodiment --seeds 1 --smoke"
    )
    assert r["state_index_2"] == {"pusht": "block_x", "aloha": "right_grip"}
    assert r["git"]["commit"] and r["platform"]["cpu_model"] is not None and r["platform"]["kernel_path"]
    (row,) = r["rows"]
    c, f, steps = r["config"], row["frames"], row["steps"]
    # steps matched by passes: each per-robot arm epochs passes over its rows, the shared arms over both
    assert steps["pusht_only"] == math.ceil(c["epochs"] * f["pusht"] / c["batch_size"])
    assert steps["aloha_only"] == math.ceil(c["epochs"] * f["aloha"] / c["batch_size"])
    assert steps["shared"] == steps["shared_id"] == math.ceil(c["epochs"] * sum(f.values()) / c["batch_size"])
    assert abs(steps["shared"] - steps["pusht_only"] - steps["aloha_only"]) <= 1
    want = {"pusht_only": ["pusht"], "aloha_only": ["aloha"], "shared": ["pusht", "aloha"]}
    want |= {"shared_id": ["pusht", "aloha"], "shared_id_swapped": ["pusht", "aloha"]}
    assert {a: sorted(v) for a, v in r["pooled"].items()} == {a: sorted(v) for a, v in want.items()}
    assert all(q["episodes"] == 1 for v in r["pooled"].values() for q in v.values())
    assert "wrote" in p.stdout


@pytest.mark.parametrize("bad", [["--seeds", "0"], ["--epochs", "-1"], ["--bogus"], ["--lr", "nan"]])
def test_a_bad_flag_is_one_line_and_exit_2_before_any_work(tmp_path, bad):
    out = tmp_path / "never"
    p = run_script("-m", "tools.embodiment", *bad, "--out", out, check=False)
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and err[0].startswith("error:"), p.stderr
    assert "Traceback" not in p.stderr and not out.exists()


def _readme_paragraph(command: str) -> str:
    """The README's paragraph that gives objective 2's numbers: the one naming the command."""
    paras = (ROOT / "README.md").read_text(encoding="utf-8").split("\n\n")
    (para,) = [p for p in paras if f"`{command}`" in p]
    return " ".join(para.split())


def test_the_readme_gives_the_kept_numbers_recounted_from_their_rows():
    """results/embodiment.json's pooled rates recounted from its per-seed rows (successes, Wilson
    interval), and each arm's count, rate and interval on each robot in the README's paragraph."""
    r = json.loads(KEPT.read_text())
    assert r["kind"] == "embodiment" and "--smoke" not in r["command"]
    assert r["git"]["commit"] and r["platform"]["cpu_model"] and r["platform"]["kernel_path"]
    n_eval, seeds = r["config"]["eval_episodes"], len(r["rows"])
    para = _readme_paragraph(r["command"])
    assert f"seeds 0..{seeds - 1}" in para
    for arm, by_robot in r["pooled"].items():
        for robot, q in by_robot.items():
            key = ("swapped_id", robot) if arm == "shared_id_swapped" else ("success", arm, robot)
            per_seed = [
                row[key[0]][key[1]] if len(key) == 2 else row[key[0]][key[1]][key[2]] for row in r["rows"]
            ]
            k, n = sum(round(v * n_eval) for v in per_seed), n_eval * seeds
            assert (q["successes"], q["episodes"]) == (k, n), (arm, robot)
            lo, hi = bc.wilson(k / n, n)
            assert q["ci95"] == pytest.approx([lo, hi], abs=1e-4), (arm, robot)
            assert f"{k}/{n} = {k / n:.3f} [{lo:.3f}, {hi:.3f}]" in para, (arm, robot)
    ups = {
        k: sum(v > 0 for v in r["differences"][f"{k}_vs_aloha_only_on_aloha"]["per_seed"])
        for k in ("shared", "shared_id")
    }
    if "both above the own policy" in para:
        assert f"both above the own policy on {seeds} of {seeds} seeds" in para and set(ups.values()) == {
            seeds
        }
    for name, d in r["differences"].items():
        arm, rest = name.split("_vs_")
        base, robot = rest.split("_on_")
        got = [row["success"][arm][robot] - row["success"][base][robot] for row in r["rows"]]
        assert d["per_seed"] == pytest.approx(got, abs=1e-4) and d["mean"] == pytest.approx(
            np.mean(got), abs=1e-4
        )


def test_the_poster_strip_reads_the_kept_measurement():
    from ch37 import code_files, poster

    assert poster.kept_embodiment(KEPT.with_name("absent.json")) is None  # no kept run: the strip as before
    assert "results/embodiment.json" in code_files()  # a new kept run is a new poster, not a cache replay
    r = poster.kept_embodiment()
    assert r is not None and r == json.loads(KEPT.read_text())
    cross = {"padded_action_dim": 6, "embodiments": [], "state_index_2_means": {}, "padded_dim_max_grad": 0.0}
    strip = poster._strip(cross)
    assert poster.measured_embodiment(r) in strip and r["command"] in strip
    for robot in ("pusht", "aloha"):
        q = r["pooled"]["shared_id"][robot]
        assert f"<b>{q['rate']:.2f}</b> [{q['ci95'][0]:.2f}, {q['ci95'][1]:.2f}]" in strip


def test_the_pile_is_the_wrangle_regions_padding_mask_and_id():
    """tools.embodiment's pile against ex2's specification of the wrangle step (exercises/checks.py's
    expected_mix): each robot standardized with its own statistics, PushT's actions in columns 0..1 and
    zeros after, the mask 1 on real dimensions only, the one-hot id of the embodiment (PushT 0, ALOHA 1)."""
    from exercises.checks import expected_mix
    from tools import embodiment as emb

    rng = np.random.default_rng(0)
    demos = {
        "pusht": {"observation.state": rng.normal(size=(7, 10)), "action": rng.normal(size=(7, 2))},
        "aloha": {"observation.state": rng.normal(size=(5, 10)), "action": rng.normal(size=(5, 6))},
    }
    demos["pusht"]["observation.state"][:, 6:] = 0.3  # PushT's constant target pose: centred, not / 0
    stats = {
        r: {"state": emb.stats_of(d["observation.state"]), "action": emb.stats_of(d["action"])}
        for r, d in demos.items()
    }
    data = emb.arm_data(demos, stats)
    z = {r: emb.standardize(d["action"], stats[r]["action"]) for r, d in demos.items()}
    actions, mask, ids = expected_mix(z["pusht"], z["aloha"])
    for arm in ("shared", "shared_id"):
        x, y, m = data[arm]
        np.testing.assert_allclose(y, actions, rtol=1e-6)
        assert np.array_equal(m, mask) and x.shape == (12, 12) and np.all(x[:7, 6:10] == 0)
    assert (
        np.array_equal(data["shared_id"][0][:, 10:], np.eye(2)[ids]) and not data["shared"][0][:, 10:].any()
    )
    assert np.array_equal(data["pusht_only"][2], mask[:7]) and np.array_equal(data["aloha_only"][2], mask[7:])
