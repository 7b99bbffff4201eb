"""The Scale Lab (scale_lab.py) at smoke size: real MuJoCo, real LeRobot, a real local Ray.

The same smoke lab run with local processes and on a private local Ray must give the same
scale_lab.json once its "seconds" fields are dropped; its re-solve point at N = 36 must be the
chapter's augmented_full arm at matching flags (scale_data.py, same data, steps and weights)."""

import json

import pytest
from conftest import ROOT, run_script


def lab(*args, check=True):
    return run_script(ROOT / "scale_lab.py", *args, check=check)


def without_seconds(obj):
    if isinstance(obj, dict):
        return {k: without_seconds(v) for k, v in obj.items() if k != "seconds"}
    if isinstance(obj, list):
        return [without_seconds(v) for v in obj]
    return obj


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    out = tmp_path_factory.mktemp("lab") / "local"
    p = lab("--smoke", "--out", out)
    assert "finished in" in p.stdout
    return out


def test_smoke_lab_writes_every_point_under_the_budget_rule(local):
    r = json.loads((local / "scale_lab.json").read_text())
    assert (local / "scale_lab.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (local / "scale_lab.rrd").stat().st_size > 0
    cfg = r["config"]
    assert (
        cfg["n"] == [12, 24, 36] and cfg["seeds"] == [0, 1] and r["command"] == "python scale_lab.py --smoke"
    )
    pts = {(p["curve"], p["n"], p["seed"]): p for p in r["points"]}
    assert len(pts) == len(r["points"]) == 4 * 3 * 2
    for s in cfg["seeds"]:
        for n in cfg["n"]:
            fresh, resolve, replay = (pts[(c, n, s)] for c in ("fresh", "resolve", "replay"))
            fixed = pts[("resolve_fixed", n, s)]
            assert fresh["steps"] == resolve["steps"]  # one budget per N
            if replay["demos"] == n:
                assert replay["steps"] == resolve["steps"]
            else:  # replay fell short of N: the same rule at the demos it kept
                assert replay["steps"] == -(-cfg["epochs"] * replay["frames"] // cfg["batch_size"])
            assert resolve["steps"] == -(-cfg["epochs"] * resolve["frames"] // cfg["batch_size"])
            assert fixed["steps"] == r["fixed_steps"][str(s)] > resolve["steps"]  # N = 108's budget
            assert fresh["demos"] == resolve["demos"] == n and 12 <= replay["demos"] <= n
            assert fixed["frames"] == resolve["frames"]
            for p in (fresh, resolve, replay, fixed):
                lo, hi = p["ci95"]
                assert 0 <= lo <= p["success"] <= hi <= 1 and p["seconds"] > 0
        # N = 12 is the 12 sources for every curve at the same budget: one and the same run
        same = [pts[(c, 12, s)] for c in ("fresh", "resolve", "replay")]
        assert len({json.dumps(without_seconds(p | {"curve": ""}), sort_keys=True) for p in same}) == 1
        assert 0 < r["expert"]["per_seed"][str(s)] <= 1
        for mode in ("resolve", "replay"):
            g = r["generation"][mode][str(s)]
            assert 0 < g["attempts"] <= g["cap"] * 12 and g["kept"] <= g["attempts"]
            assert g["attempts"] == g["kept"] + sum(g["failures"].values())
    assert r["generation"]["resolve"]["0"]["kept"] == 96  # 8 per source: the set at N = 108


def test_local_ray_gives_the_same_json(local, tmp_path):
    """A private local Ray started by the command (2 CPUs) and shut down at its end."""
    lab("--smoke", "--ray", "--workers", "2", "--no-rerun", "--out", tmp_path / "ray")
    got = json.loads((tmp_path / "ray" / "scale_lab.json").read_text())
    want = json.loads((local / "scale_lab.json").read_text())
    assert without_seconds(got) == without_seconds(want)


def test_the_resolve_point_is_the_chapters_augmented_full_arm(local, tmp_path):
    """scale_data.py at the smoke lab's flags (12 sources, 2 re-solves each = N 36, seed 0)."""
    flags = ["--epochs", "5", "--hidden_dim", "32", "--batch_size", "64", "--eval_episodes", "4"]
    flags += ["--source_episodes", "12", "--aug_per_demo", "2", "--no-rerun", "--no-cache"]
    run_script(ROOT / "scale_data.py", "--smoke", "--seed", "0", *flags, "--out", tmp_path / "sd")
    arm = json.loads((tmp_path / "sd" / "metrics.json").read_text())["arms"]["augmented_full"]
    r = json.loads((local / "scale_lab.json").read_text())
    (p,) = [p for p in r["points"] if (p["curve"], p["n"], p["seed"]) == ("resolve", 36, 0)]
    assert {k: p[k] for k in ("frames", "steps", "final_loss", "success", "ci95")} == {
        k: arm[k] for k in ("frames", "steps", "final_loss", "success", "ci95")
    }


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--n", "12", "20"], "--n 20"),
        (["--n", "0"], "--n 0"),
        (["--seeds", "-1"], "--seeds"),
        (["--eval_episodes", "0"], "--eval_episodes"),
        (["--n", "x"], "invalid int value"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv, needle, tmp_path):
    p = lab(*argv, "--out", tmp_path / "o", check=False)
    assert p.returncode == 2 and p.stdout == ""
    assert p.stderr.startswith("error: ") and p.stderr.count("\n") == 1 and needle in p.stderr
    assert not (tmp_path / "o").exists()


def test_meta_writes_the_scale_lab_section_from_the_json_and_keeps_it_otherwise(local, tmp_path):
    import yaml
    from test_packaging import sweep_files

    a, b = sweep_files(tmp_path, [0.1, 0.2], [0.0, 0.1, 0.2])
    meta = tmp_path / "meta.yaml"
    kept = yaml.safe_load((ROOT / "meta.yaml").read_text())["scale_lab"]  # ex3's answer reads its curves
    meta.write_text(yaml.safe_dump({"scale_lab": kept}))
    base = ["-m", "tools.meta", "--sweep", a, "--aug-sweep", b, "--meta", meta, "--replay", tmp_path / "none"]
    run_script(*base, "--scale-lab", tmp_path / "absent.json")
    assert yaml.safe_load(meta.read_text())["scale_lab"] == kept  # no lab: left as found
    run_script(*base, "--scale-lab", local / "scale_lab.json")
    sec = yaml.safe_load(meta.read_text())["scale_lab"]
    r = json.loads((local / "scale_lab.json").read_text())
    assert sec["provisional"] is True and sec["command"] == "python scale_lab.py --smoke"
    assert sec["seeds"] == [0, 1] and set(sec["curves"]) == {"fresh", "resolve", "replay", "resolve_fixed"}
    row = sec["curves"]["resolve"][36]
    assert row["success"] == r["curves"]["resolve"]["36"]["success"] and row["demos"] == 36
    assert row["steps"] == r["curves"]["resolve"]["36"]["steps"]
    assert sec["generation"]["resolve"]["kept"] == 192
    bad = tmp_path / "bad.json"
    bad.write_text('{"kind": "seeds"}')
    p = run_script(*base, "--scale-lab", bad, check=False)
    assert p.returncode == 2 and p.stderr.startswith("error: ") and p.stderr.count("\n") == 1
