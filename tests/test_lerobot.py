"""LeRobot's own policies on our sets: lerobot-train reads a set we write as it is (PushT and ALOHA,
generated or grown), and a checkpoint it writes is rolled out in our PushT env by tools.lerobot eval.
Training runs only under -m slow."""

import json
import math
import os
import shutil
import sys
from pathlib import Path

import pytest
from conftest import ROOT, run_script

TRAIN = Path(sys.executable).with_name("lerobot-train")  # the console script of the `train` extra


@pytest.fixture(scope="module")
def grown(tmp_path_factory):
    """A tiny PushT set grown by the data engine: 2 generated demos, 1 re-solved start each."""
    d = tmp_path_factory.mktemp("sets")
    run_script(ROOT / "gen_demos_pusht.py", "--episodes", "2", "--seed", "0", "--out", d / "src", "--quiet")
    run_script(
        ROOT / "augment_demos.py",
        "--src",
        d / "src",
        "--per_demo",
        "1",
        "--out",
        d / "aug",
        "--workers",
        "1",
        "--quiet",
    )
    return d / "aug"


def train(root: Path, out: Path, policy: str, *policy_flags: str) -> Path:
    """lerobot-train for 2 steps on `root`: the dataset, the policy type and the length are all it
    needs, plus push_to_hub=false (LeRobot asks for a hub repo id otherwise); the batch, the loader
    workers and the device only keep the test small. Returns the step-2 pretrained_model folder."""
    run_script(
        TRAIN,
        "--dataset.repo_id=local/pusht_aug",
        f"--dataset.root={root}",
        f"--policy.type={policy}",
        "--steps=2",
        "--policy.push_to_hub=false",
        f"--output_dir={out}",
        "--batch_size=2",
        "--num_workers=0",
        "--policy.device=cpu",
        *policy_flags,
    )
    return out / "checkpoints" / "000002" / "pretrained_model"


@pytest.mark.slow
@pytest.mark.parametrize("policy", ["diffusion", "act"])
def test_lerobot_train_runs_on_a_set_we_write(grown, tmp_path, policy):
    model = train(grown, tmp_path / "train", policy)
    assert (model / "config.json").is_file() and (model / "model.safetensors").is_file()
    cfg = json.loads((model / "config.json").read_text())
    assert cfg["type"] == policy
    assert cfg["input_features"]["observation.environment_state"]["shape"] == [8]
    shutil.rmtree(tmp_path / "train")  # the default diffusion U-Net's checkpoint is about 1 GB


@pytest.fixture(scope="module")
def grown_aloha(tmp_path_factory):
    """Two tiny ALOHA sets grown by the data engine from 2 generated demos, 1 attempt each: one
    re-solved, one replayed subtask by subtask (issue 29)."""
    d = tmp_path_factory.mktemp("aloha")
    run_script(ROOT / "gen_demos_aloha.py", "--episodes", "2", "--seed", "0", "--out", d / "src", "--quiet")
    for mode in ("resolve", "replay"):
        flags = ["--per_demo", "1", "--mode", mode, "--out", d / mode, "--workers", "1", "--quiet"]
        run_script(ROOT / "augment_demos.py", "--src", d / "src", *flags)
    return d


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["resolve", "replay"])
def test_lerobot_train_runs_on_a_grown_aloha_set(grown_aloha, tmp_path, mode):
    """lerobot-train (ACT, 2 steps) on an ALOHA set the engine grew, as it is: 6-D actions and the
    ALOHA env state among the policy's inputs."""
    import aloha_env

    model = train(grown_aloha / mode, tmp_path / "train", "act")
    cfg = json.loads((model / "config.json").read_text())
    assert cfg["type"] == "act"
    assert cfg["output_features"]["action"]["shape"] == [aloha_env.ACT_DIM]
    assert cfg["input_features"]["observation.state"]["shape"] == [len(aloha_env.STATE_NAMES)]
    env_state = cfg["input_features"]["observation.environment_state"]["shape"]
    assert env_state == [len(aloha_env.ENV_STATE_NAMES)]


@pytest.mark.slow
def test_a_lerobot_checkpoint_rolls_out_in_our_env(grown, tmp_path):
    from bc_recipe import wilson
    from ch37.seeds import env_seed

    # a small U-Net with 10 denoising steps: the rollout is what is tested, not the policy
    flags = ("--policy.down_dims=[32,64]", "--policy.num_inference_steps=10")
    model = train(grown, tmp_path / "train", "diffusion", *flags)
    out = tmp_path / "eval.json"
    p = run_script(
        "-m",
        "tools.lerobot",
        "eval",
        "--policy",
        model,
        "--seed",
        "0",
        "--episodes",
        "2",
        "--device",
        "cpu",
        "--out",
        out,
    )
    assert "success" in p.stdout and str(out) in p.stdout
    r = json.loads(out.read_text())
    assert r["kind"] == "lerobot_eval" and r["policy_type"] == "diffusion" and r["episodes"] == 2
    assert 0.0 <= r["success"] <= 1.0 and r["successes"] == sum(e["success"] for e in r["per_episode"])
    assert [e["seed"] for e in r["per_episode"]] == [env_seed(0, "eval", j) for j in range(2)]
    assert all(1 <= e["steps"] <= 300 for e in r["per_episode"])
    assert r["ci95"] == pytest.approx(wilson(r["success"], 2), abs=1e-4)


def test_lerobot_eval_bad_policy_is_one_line(tmp_path):
    (tmp_path / "config.json").write_text('{"type": "no_such_policy"}')
    for policy in (tmp_path / "absent", tmp_path):
        p = run_script("-m", "tools.lerobot", "eval", "--policy", policy, "--episodes", "1", check=False)
        assert p.returncode == 2 and p.stderr.strip().startswith("error:"), p.stderr
        assert len(p.stderr.strip().splitlines()) == 1


def test_lerobot_eval_of_a_checkpoint_with_nan_weights_is_one_line(tmp_path):
    """Issue 42 #5: a checkpoint whose weights are NaN ended in a 38-line traceback (the env's `ValueError:
    non-finite action [nan nan]`): a policy that outputs NaN is a bad input, one line naming it. The
    checkpoint is LeRobot's own diffusion policy saved untrained (no training: seconds), its weights NaN."""
    import torch
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.diffusion.configuration_diffusion import DiffusionConfig
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors

    widths = {"observation.state": 10, "observation.environment_state": 8, "action": 2}
    kinds = {"observation.state": FeatureType.STATE, "observation.environment_state": FeatureType.ENV}
    feats = {k: PolicyFeature(kinds[k], (n,)) for k, n in widths.items() if k in kinds}
    act = {"action": PolicyFeature(FeatureType.ACTION, (2,))}
    cfg = DiffusionConfig(
        input_features=feats, output_features=act, down_dims=(32, 64), num_inference_steps=2
    )
    cfg.device = "cpu"
    policy = get_policy_class(cfg.type)(cfg)
    with torch.no_grad():
        for w in policy.parameters():
            w.fill_(float("nan"))
    model = tmp_path / "pretrained_model"
    policy.save_pretrained(model)
    unit = {"min": 0.0, "max": 1.0, "mean": 0.0, "std": 1.0}  # statistics the processors normalize with
    stats = {k: {s: torch.full((n,), v) for s, v in unit.items()} for k, n in widths.items()}
    for processor in make_pre_post_processors(cfg, dataset_stats=stats):
        processor.save_pretrained(model)
    out = tmp_path / "eval.json"
    p = run_script(
        "-m",
        "tools.lerobot",
        "eval",
        "--policy",
        model,
        "--episodes",
        "1",
        "--device",
        "cpu",
        "--out",
        out,
        check=False,
    )
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1 and "Traceback" not in p.stderr, p.stderr[-3000:]
    assert err[0].startswith(f"error: --policy {model} gives a non-finite action"), err
    assert not out.exists()


def test_lerobot_lab_samples_are_lerobot_datasets_items(grown):
    """tools.lerobot lab's own loader gives, for every training sample, what lerobot-train's loader
    gives: LeRobotDataset's item (observation windows, action chunk, pad flags) at the frames its
    EpisodeAwareSampler draws."""
    import numpy as np
    from lerobot.datasets import EpisodeAwareSampler
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from lerobot_v3.dataset import ENV_STATE_KEY, load_arrays
    from tools import lerobot as lerobot_lab

    info = json.loads((grown / "meta" / "info.json").read_text())
    a = load_arrays(grown, keys=("observation.state", "action", "episode_index"))
    episodes = [
        {k: a[k][a["episode_index"] == e] for k in ("observation.state", "action")}
        for e in np.unique(a["episode_index"])
    ]
    policy, _, _ = lerobot_lab.policy_and_processors({}, seed=0)
    cfg = policy.config
    lengths = [len(e["action"]) for e in episodes]
    s = lerobot_lab.samples(lengths, cfg)
    frames = lerobot_lab.frame_arrays(episodes)
    fps = info["fps"]
    delta = {
        k: [i / fps for i in cfg.observation_delta_indices] for k in ("observation.state", ENV_STATE_KEY)
    }
    delta["action"] = [i / fps for i in cfg.action_delta_indices]
    ds = LeRobotDataset("local/pusht_aug", root=grown, delta_timestamps=delta, video_backend="pyav")
    sampler = EpisodeAwareSampler(
        ds.meta.episodes["dataset_from_index"],
        ds.meta.episodes["dataset_to_index"],
        drop_n_last_frames=cfg.drop_n_last_frames,
    )
    assert sorted(sampler) == s["rows"].tolist() and len(s["rows"]) > 0
    ours = lerobot_lab.batch_of(frames, s, np.arange(len(s["rows"])))
    for j, row in enumerate(s["rows"]):
        item = ds[int(row)]
        for key in (
            "observation.state",
            ENV_STATE_KEY,
            "action",
            "action_is_pad",
            "observation.state_is_pad",
        ):
            assert np.array_equal(item[key].numpy(), ours[key][j].numpy()), (key, row)
    assert ours["action_is_pad"].any() and ours["observation.state_is_pad"].any()  # both edges met


@pytest.mark.slow
def test_lerobot_lab_runs_end_to_end(tmp_path):
    """A few steps on each point and one start: the pipeline, its JSON and the saved checkpoint."""
    p = run_script(
        "-m",
        "tools.lerobot",
        "lab",
        "--steps",
        "3",
        "--seeds",
        "0",
        "--eval_episodes",
        "1",
        "--out",
        tmp_path,
    )
    r = json.loads((tmp_path / "lerobot_lab.json").read_text())
    assert set(r["table"]) == {"source", "fresh", "resolve", "exchange_rate"}, p.stdout
    fresh, resolve = (json.loads((tmp_path / f"{k}_seed0.json").read_text()) for k in ("fresh", "resolve"))
    assert (fresh["demos"], resolve["demos"]) == (108, 108) and fresh["frames"] != resolve["frames"]
    assert (tmp_path / "resolve_seed0" / "pretrained_model" / "config.json").is_file()


@pytest.mark.slow
def test_lerobot_lab_checkpoint_rollouts_leave_the_training_as_it_was(grown):
    """The pilot's rollouts mid-training (--eval_every) do not change the run: the same loss at every
    step as a run without them, and they do roll out (a check that never ran would pass the first)."""
    import numpy as np

    from lerobot_v3.dataset import load_arrays
    from tools import lerobot as lerobot_lab

    a = load_arrays(grown, keys=("observation.state", "action", "episode_index"))
    episodes = [
        {k: a[k][a["episode_index"] == e] for k in ("observation.state", "action")}
        for e in np.unique(a["episode_index"])
    ]
    seen = []
    check = lerobot_lab.rollout_check([7], seen)
    plain = lerobot_lab.train(episodes, 4, 0, 1e-3, log_every=1)[3]
    checked = lerobot_lab.train(episodes, 4, 0, 1e-3, log_every=1, check=check, check_every=2)[3]
    assert [c["step"] for c in seen] == [2, 4] and all(c["successes"] in (0, 1) for c in seen)
    assert checked == plain and len(plain) == 4


# the kept evaluations of each LeRobot row: (folder, its three sets, the file each run leaves, that file's
# per-episode successes and max rewards, read here without the tool)
ROWS = {
    "gym_pusht": (  # lerobot-eval's own eval_info.json of docs/gym_pusht.md's row
        ROOT / "results" / "gym_pusht_lerobot",
        ("sources", "resolved", "fresh"),
        "eval_info.json",
        lambda r: (r["per_task"][0]["metrics"]["successes"], r["per_task"][0]["metrics"]["max_rewards"]),
    ),
    "aloha_transfer_cube": (  # tools.lerobot eval's JSON of docs/engine.md's ACT row
        ROOT / "results" / "aloha_transfer_cube_act",
        ("sources", "replayed", "fresh"),
        "lerobot_eval.json",
        lambda r: ([e["success"] for e in r["per_episode"]], [e["max_reward"] for e in r["per_episode"]]),
    ),
}


@pytest.mark.parametrize("task", ROWS)
def test_the_lerobot_row_is_counted_from_its_evaluations_own_files(tmp_path, task):
    """Issue 49 #1, issue 50 #5: `tools.lerobot table` counts each set's successes, its Wilson interval,
    the paired per-seed differences and the max reward's start-by-start difference from the evaluations
    kept under results/ (lerobot-eval's eval_info.json on gym-pusht; tools.lerobot eval's JSON on
    transfer-cube), recounted here from the files; a seed missing a set is left out, and a file that is
    not its evaluation is one `error:` line naming it."""
    from bc_recipe import wilson

    kept, sets, file, read = ROWS[task]
    grown = sets[1]

    def info(seed, k):  # (successes, max rewards) per episode
        return read(json.loads((kept / f"seed{seed}" / f"eval_{k}" / file).read_text()))

    run = tmp_path / "run"
    shutil.copytree(kept, run)
    shutil.copytree(run / "seed0", run / "seed9")  # a seed not finished: one set's evaluation missing
    shutil.rmtree(run / "seed9" / "eval_fresh")
    out = tmp_path / "t.json"
    run_script("-m", "tools.lerobot", "table", run, "--json", out)
    t = json.loads(out.read_text())
    seeds = sorted(d.name[4:] for d in kept.glob("seed*"))
    assert t["task"] == task and sorted(t["seeds"]) == seeds and len(seeds) == 3
    rate = {}
    for k in sets:
        wins = [info(s, k)[0] for s in seeds]
        rate[k] = [sum(w) / len(w) for w in wins]
        n = sum(map(len, wins))
        assert t["pooled"][k]["successes"] == sum(map(sum, wins)) and t["pooled"][k]["episodes"] == n >= 150
        assert t["pooled"][k]["ci95"] == pytest.approx(wilson(sum(map(sum, wins)) / n, n), abs=1e-4)
    got = t["paired"][f"{grown} - sources"]
    want = [a - b for a, b in zip(rate[grown], rate["sources"], strict=True)]
    assert [got["success"][s] for s in seeds] == pytest.approx(want, abs=1e-4)
    best = {k: [x for s in seeds for x in info(s, k)[1]] for k in (grown, "sources")}
    each = [a - b for a, b in zip(best[grown], best["sources"], strict=True)]
    paired = got["max_reward_paired"]
    assert paired["episodes"] == len(each) and paired["mean"] == pytest.approx(
        sum(each) / len(each), abs=1e-4
    )
    (run / "seed1" / "eval_sources" / file).write_text('{"per_task": []}')
    p = run_script("-m", "tools.lerobot", "table", run, check=False)
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), p.stderr
    assert f"seed1/eval_sources/{file}" in lines[0]


def fake_row(root: Path, task: str, n: int = 4, seeds=(0, 1)) -> dict:
    """A small run folder shaped like ROWS[task]'s kept one: each seed's three sets scored on the same `n`
    starts (set j wins its first j + 1), its train logs ending in a `loss:`; returns {set: file of seed 0}."""
    _, sets, file, _ = ROWS[task]
    first = {}
    for s in seeds:
        for j, k in enumerate(sets):
            wins, best = [e <= j for e in range(n)], [float(e <= j) * 4 for e in range(n)]
            if file == "eval_info.json":
                metrics = {"max_rewards": [b / 4 for b in best], "successes": wins}
                r = {"per_task": [{"task_group": "pusht", "task_id": 0, "metrics": metrics}]}
            else:
                eps = [
                    {"seed": (3 * s + 2) * 10**6 + e, "success": w, "steps": 400, "max_reward": b}
                    for e, (w, b) in enumerate(zip(wins, best, strict=True))
                ]
                r = {"kind": "lerobot_eval", "episodes": n, "successes": sum(wins), "per_episode": eps}
            path = root / f"seed{s}" / f"eval_{k}" / file
            path.parent.mkdir(parents=True)
            path.write_text(json.dumps(r))
            (root / f"seed{s}" / f"train_{k}.log").write_text("step:100 smpl:800 loss:0.512 grdn:1.2\n")
            first.setdefault(k, path)
    return first


@pytest.mark.parametrize("task", ROWS)
def test_the_lerobot_table_refuses_a_damaged_evaluation_in_one_line_naming_it(tmp_path, task, capsys):
    """Issue 62 #8: an evaluation with no episodes, a max reward of NaN or Infinity (or a word), one set
    scored on fewer starts than the others of its seed, a success that is the word "false" (once counted a
    success: 6/150 read 7/150) and a train log cut after `loss:` were tracebacks or a silent recount: each
    is one `error:` line naming the file, exit 2."""
    _, sets, file, _ = ROWS[task]
    run = tmp_path / "run"
    ours = file != "eval_info.json"

    def damage_reward(value):
        def f(r):
            if ours:
                r["per_episode"][1]["max_reward"] = value
            else:
                r["per_task"][0]["metrics"]["max_rewards"][1] = value

        return f

    def false_word(r):
        if ours:
            r["per_episode"][2]["success"] = "false"
        else:
            r["per_task"][0]["metrics"]["successes"][2] = "false"

    def fewer(r):
        if ours:
            del r["per_episode"][2:]
            r["episodes"], r["successes"] = 2, sum(e["success"] for e in r["per_episode"])
        else:
            for k in ("max_rewards", "successes"):
                del r["per_task"][0]["metrics"][k][2:]

    def empty(r):
        if ours:
            r["per_episode"], r["episodes"], r["successes"] = [], 0, 0
        else:
            r["per_task"][0]["metrics"].update(max_rewards=[], successes=[])

    cases = {
        "no episodes": (empty, "no episodes"),
        "nan": (damage_reward(math.nan), "max reward"),
        "inf": (damage_reward(math.inf), "max reward"),
        "word": (damage_reward("4"), "max reward"),
        '"false"': (false_word, "success"),
        "10 of 50": (fewer, "starts"),
    }
    from ch37.errors import DataError
    from tools import lerobot as tool

    fake_row(tmp_path / "good", task)
    assert tool.table_main([str(tmp_path / "good")]) == 0  # the fake row itself is read
    assert "pooled" in capsys.readouterr().out
    for name, (hurt, needle) in cases.items():  # in-process: each would be a subprocess importing torch
        shutil.rmtree(run, ignore_errors=True)
        path = fake_row(run, task)[sets[1]]
        r = json.loads(path.read_text())
        hurt(r)
        path.write_text(json.dumps(r))
        with pytest.raises(DataError) as e:
            tool.table_main([str(run)])
        assert f"seed0/eval_{sets[1]}/{file}" in str(e.value) and needle in str(e.value), (name, e.value)
        assert "\n" not in str(e.value) and "pooled" not in capsys.readouterr().out, name
    if task == "gym_pusht":  # the last case as a user meets it (once: a subprocess imports torch anew)
        p = run_script("-m", "tools.lerobot", "table", run, check=False)
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), p.stderr
    shutil.rmtree(run)
    fake_row(run, task)
    (run / "seed1" / "train_fresh.log").write_text("step:100 smpl:800 loss:")  # cut as it was written
    with pytest.raises(DataError, match="seed1/train_fresh.log.*loss:"):
        tool.table_main([str(run)])


def test_the_lerobot_row_script_refuses_a_task_it_has_no_row_for(tmp_path):
    """tools/lerobot_row.sh names its tasks: another task, or no OUT folder, is one `error:` line and exit
    2, before anything is made."""
    import subprocess

    for args in (["pusht", str(tmp_path / "out")], ["aloha_transfer_cube"]):
        p = subprocess.run(["bash", ROOT / "tools" / "lerobot_row.sh", *args], capture_output=True, text=True)
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), p.stderr
    assert not (tmp_path / "out").exists()


def test_the_lerobot_row_script_checks_every_argument_before_any_work(tmp_path):
    """Issue 62 #7: SEEDS, STEPS, EPISODES and LANES are whole numbers from 1 up (SEEDS=0 once ran no seed
    and pointed at a log it never wrote; STEPS=abc started generating sets), EPISODES at most one seed
    block, OUT a folder, at most six arguments, and the GPU check's environment (DEVICE cpu or cuda,
    WORKERS from 1 up): each wrong one is one `error:` line naming it, exit 2, before anything is made
    (OUT is not created)."""
    import subprocess

    out, file = tmp_path / "out", tmp_path / "a_file"
    file.write_text("mine")
    cases = {  # the arguments after TASK OUT -> the name the line must hold
        ("0",): "SEEDS",
        ("abc",): "SEEDS",
        ("1", "abc"): "STEPS",
        ("1", "-5"): "STEPS",
        ("1", "10", "0"): "EPISODES",
        ("1", "10", "1000001"): "EPISODES",
        ("1", "10", "5", "1.5"): "LANES",
        ("1", "10", "5", "1", "extra"): "extra",
        ("1", "99999999999999999999"): "STEPS",
        ("DEVICE=gpu", "1"): "DEVICE",
        ("WORKERS=0", "1"): "WORKERS",
        ("WORKERS=two", "1"): "WORKERS",
    }
    for rest, name in cases.items():
        env = dict(os.environ, **dict(a.split("=") for a in rest if "=" in a))
        p = subprocess.run(
            [
                "bash",
                ROOT / "tools" / "lerobot_row.sh",
                "aloha_transfer_cube",
                out,
                *[a for a in rest if "=" not in a],
            ],
            capture_output=True,
            text=True,
            timeout=60,
            env=env,
        )
        lines = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), (rest, p.stderr)
        assert name in lines[0] and not out.exists(), (rest, p.stderr)
    p = subprocess.run(
        ["bash", ROOT / "tools" / "lerobot_row.sh", "gym_pusht", file], capture_output=True, text=True
    )
    lines = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(lines) == 1 and lines[0].startswith("error:"), p.stderr
    assert str(file) in lines[0] and file.read_text() == "mine"


def tiny_act(widths: dict, folder: Path | None = None):
    """LeRobot's ACT, untrained and tiny (dim_model 64, one encoder layer, chunks of 10), reading the
    features `widths` names ({key: width}, action among them), saved with unit-statistics processors
    to `folder` when given; returns the policy."""
    import torch
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.factory import get_policy_class, make_pre_post_processors

    kinds = {"observation.state": FeatureType.STATE, "observation.environment_state": FeatureType.ENV}
    feats = {k: PolicyFeature(kinds[k], (n,)) for k, n in widths.items() if k in kinds}
    act = {"action": PolicyFeature(FeatureType.ACTION, (widths["action"],))}
    cfg = ACTConfig(
        input_features=feats,
        output_features=act,
        dim_model=64,
        n_encoder_layers=1,
        chunk_size=10,
        n_action_steps=10,
    )
    cfg.device = "cpu"
    policy = get_policy_class(cfg.type)(cfg)
    if folder is not None:
        policy.save_pretrained(folder)
        unit = {"min": 0.0, "max": 1.0, "mean": 0.0, "std": 1.0}
        stats = {k: {s: torch.full((n,), v) for s, v in unit.items()} for k, n in widths.items()}
        for processor in make_pre_post_processors(cfg, dataset_stats=stats):
            processor.save_pretrained(folder)
    return policy


def test_lerobot_eval_reads_a_tasks_state_and_environment_state_as_its_sets_hold_them(tmp_path):
    """Issue 50 #5: tools.lerobot eval --task aloha_transfer_cube feeds an ACT that reads transfer-cube's
    sets (observation.state: the 14 joints; observation.environment_state: the cube's pose) those columns
    of the env's observation, and refuses one that reads PushT's widths in one line."""
    import numpy as np

    from datagen import known_tasks
    from tools import lerobot as tool

    spec = known_tasks()["aloha_transfer_cube"].spec
    policy = tiny_act({"observation.state": 14, "observation.environment_state": 7, "action": 14})
    obs = np.arange(21, dtype=np.float32)
    batch = tool.observation_builder(policy, spec, "aloha_transfer_cube")(obs)
    assert batch["observation.state"].tolist() == [list(range(14))]
    assert batch["observation.environment_state"].tolist() == [list(range(14, 21))]
    assert batch["task"] == [spec.task]
    model = tmp_path / "pushts"
    tiny_act({"observation.state": 10, "observation.environment_state": 8, "action": 2}, model)
    p = run_script(
        "-m",
        "tools.lerobot",
        "eval",
        "--task",
        "aloha_transfer_cube",
        "--policy",
        model,
        "--episodes",
        "1",
        check=False,
    )
    err = p.stderr.strip().splitlines()
    assert p.returncode == 2 and len(err) == 1, p.stderr[-2000:]
    assert "observation.state has shape (10,); aloha_transfer_cube's is (14,)" in err[0], err


@pytest.mark.slow
def test_lerobot_act_trained_on_a_transfer_cube_set_rolls_out_in_our_env(tmp_path):
    """Issue 50 #5: lerobot-train's ACT (tiny, 2 steps) on a 2-episode aloha_transfer_cube set as
    gen_demos.py writes it (observation.state + observation.environment_state, no images), rolled out
    by tools.lerobot eval --task aloha_transfer_cube on 2 held-out starts, gym-aloha's success."""
    from ch37.seeds import env_seed

    data = tmp_path / "set"
    run_script(
        ROOT / "gen_demos.py", "--task", "aloha_transfer_cube", "--episodes", "2", "--out", data, "--quiet"
    )
    flags = ("--policy.dim_model=64", "--policy.n_encoder_layers=1", "--policy.chunk_size=10")
    model = train(data, tmp_path / "train", "act", *flags, "--policy.n_action_steps=10")
    cfg = json.loads((model / "config.json").read_text())
    assert cfg["input_features"]["observation.environment_state"]["shape"] == [7]
    assert cfg["input_features"]["observation.state"]["shape"] == [14]
    out = tmp_path / "eval.json"
    flags = ("--task", "aloha_transfer_cube", "--episodes", "2", "--device", "cpu", "--out", out)
    p = run_script("-m", "tools.lerobot", "eval", "--policy", model, *flags)
    assert "held-out aloha_transfer_cube starts" in p.stdout, p.stdout
    r = json.loads(out.read_text())
    assert (r["task"], r["policy_type"], r["episodes"]) == ("aloha_transfer_cube", "act", 2)
    assert [e["seed"] for e in r["per_episode"]] == [env_seed(0, "eval", j) for j in range(2)]
    assert all(1 <= e["steps"] <= 400 for e in r["per_episode"])
