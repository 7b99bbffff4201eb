"""Issue 28 #3: one definition per flag. Every command's flags are dataclass fields (ch37.config.flag): the
parser enforces each field's bound, an old spelling parses as the same flag, and a knob several commands
share has one name, default and bound everywhere."""

import ast
import dataclasses
import math
from pathlib import Path

import pytest
from conftest import ROOT, run_script

import augment_demos
import gen_demos
import scale_lab
from ch37 import config, seeds
from ch37.errors import DataError
from tools import lerobot as lerobot_eval  # its Args: `python -m tools.lerobot eval`'s flags

# the groups several commands take (Chapter is the lesson's experiment: another command's --seed or
# --eval_episodes is its own knob, with its own default, and is checked by name below)
GROUPS = (config.Recipe, config.Perturbation, config.Mode, config.Tries, config.Parallel, config.Ray)
NEEDS = {"augment_demos": ["--src", "s", "--out", "o"]}  # required flags, never opened by parse()
COMMANDS = (augment_demos, scale_lab, gen_demos, lerobot_eval)  # scale_data.py is read, not imported
# An old spelling that is another command's name for another knob, kept so documented commands work:
# gen_demos' --episodes (demos to roll out) and lerobot_eval's --episodes (now --eval_episodes).
TWO_KNOBS = {"episodes"}


def _literal(node):
    """A flag() argument as written in scale_data.py: a literal, or a name the lesson imports from
    ch37.config or ch37.seeds (POSITIVE, SIGMA_MAX, MAX_SEED, ...)."""
    if isinstance(node, ast.Name):
        return getattr(config, node.id) if hasattr(config, node.id) else getattr(seeds, node.id)
    if isinstance(node, ast.JoinedStr):  # an f-string help: its text does not matter here
        return ast.unparse(node)
    return ast.literal_eval(node)


def lesson_fields() -> dict[str, dict]:
    """scale_data.py's own flags, read from its Args class (the lesson runs when imported, so it is read)
    as {name: {"bound", "at_most", "aliases", "default"}}, and the groups it inherits, by name."""
    tree = ast.parse((ROOT / "scale_data.py").read_text(encoding="utf-8"))
    cls = next(n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == "Args")
    own = {}
    for st in cls.body:
        if isinstance(st, ast.AnnAssign) and isinstance(st.value, ast.Call) and st.value.func.id == "flag":
            kw = {k.arg: k.value for k in st.value.keywords}
            own[st.target.id] = {
                "bound": _literal(kw["bound"]) if "bound" in kw else None,
                "at_most": _literal(kw["at_most"]) if "at_most" in kw else None,
                "aliases": _literal(kw["aliases"]) if "aliases" in kw else (),
                "default": _literal(st.value.args[0]),
            }
    bases = [getattr(config, b.id) for b in cls.bases]
    return own, bases


def meta(f: dataclasses.Field) -> dict:
    return {k: f.metadata[k] for k in ("bound", "at_most", "aliases")}


def commands() -> dict[str, dict[str, dict]]:
    """{command: {flag name: its bound, at_most and aliases}} for every command with an Args dataclass."""
    own, bases = lesson_fields()
    lesson = {f.name: meta(f) for b in bases for f in config.fields(b)}
    lesson |= {name: {k: v for k, v in m.items() if k != "default"} for name, m in own.items()}
    out = {"scale_data": lesson}
    for mod in COMMANDS:
        out[mod.__name__] = {f.name: meta(f) for f in config.fields(mod.Args)}
    return out


def out_of_bound(m: dict, is_int: bool) -> list[str]:
    """Values outside a field's declared range: below its bound, above its at_most."""
    bad = {config.POSITIVE: ["0"], config.NON_NEGATIVE: ["-1"], config.FINITE: ["nan", "-0.0", "-1"]}
    bad[config.FINITE_POSITIVE] = ["0", "inf"]
    vals = list(bad.get(m["bound"], []))
    if m["at_most"] is not None:
        most = m["at_most"]
        vals.append(str(most + 1) if is_int else repr(most * 2 + 1))
    return vals


def bounded_cases():
    cases = []
    for mod in COMMANDS:
        for f in config.fields(mod.Args):
            d = f.default if f.default is not dataclasses.MISSING else f.default_factory()
            is_int = f.metadata["kw"].get("type") is int or isinstance(d, int) or isinstance(d, list)
            for v in out_of_bound(meta(f), is_int):
                cases.append(pytest.param(mod, f.name, v, id=f"{mod.__name__}-{f.name}-{v}"))
    return cases


def parse_with(mod, argv):
    if mod in (gen_demos, lerobot_eval):  # their parse is inside main(), which goes on to work
        return config.parse(mod.Args, ["--policy", "p"] * (mod is lerobot_eval) + argv)
    return mod.parse([*NEEDS.get(mod.__name__, []), *argv])


@pytest.mark.parametrize("mod,name,value", bounded_cases())
def test_every_bounded_field_is_enforced_by_the_parser(mod, name, value):
    """For every command and every field with a bound: a value outside it is one DataError naming the flag."""
    with pytest.raises(DataError) as e:
        parse_with(mod, [f"--{name}", value])
    assert str(e.value).startswith(f"--{name} must be"), str(e.value)
    assert "\n" not in str(e.value)


def test_every_bounded_flag_of_the_lesson_is_enforced(tmp_path):
    """The same for scale_data.py (run, since importing it runs the lesson): one line, exit 2, the flag
    named, nothing made; each bounded field of its Args and the groups it takes is tried once."""
    own, bases = lesson_fields()
    fields = {f.name: meta(f) for b in bases for f in config.fields(b)} | own
    ints = {f.name for b in bases for f in config.fields(b) if isinstance(f.default, int)} | {"workers"}
    ints |= {name for name, m in own.items() if type(m["default"]) is int}
    tried = 0
    for name, m in sorted(fields.items()):
        vals = out_of_bound(m, name in ints)
        if not vals:
            continue
        p = run_script(
            "scale_data.py", "--smoke", f"--{name}", vals[-1], "--out", tmp_path / "o", check=False
        )
        err = p.stderr.strip().splitlines()
        assert p.returncode == 2 and len(err) == 1 and err[0].startswith(f"error: --{name} must be"), p.stderr
        tried += 1
    assert tried >= 12 and not (tmp_path / "o").exists()


ALIASED = [
    (lerobot_eval, "eval_episodes", "episodes", "7"),
    (augment_demos, "attempts_per_demo", "per_demo", "7"),
    (augment_demos, "aug_pos_sigma", "pos_sigma", "0.05"),
    (augment_demos, "aug_yaw_sigma", "yaw_sigma", "0.25"),
    (augment_demos, "aug_mode", "mode", "replay"),
    (scale_lab, "aug_pos_sigma", "pos_sigma", "0.05"),
    (scale_lab, "aug_yaw_sigma", "yaw_sigma", "0.25"),
]


@pytest.mark.parametrize("mod,name,alias,value", ALIASED, ids=[f"{m.__name__}-{a}" for m, _, a, _ in ALIASED])
def test_an_old_spelling_parses_as_the_same_flag(mod, name, alias, value):
    new, old = parse_with(mod, [f"--{name}", value]), parse_with(mod, [f"--{alias}", value])
    assert vars(new) == vars(old) and getattr(new, name) != getattr(parse_with(mod, []), name)
    assert not hasattr(old, alias)  # one flag, one name in the program


def test_an_error_names_the_flag_as_it_was_typed():
    """Documented commands use the old spellings: their errors must name what the user typed."""
    for argv, needle in (
        (["--pos_sigma", "11"], "--pos_sigma must be at most 10"),
        (["--aug_pos_sigma", "11"], "--aug_pos_sigma must be at most 10"),
        (["--per_demo=0"], "--per_demo must be a positive integer"),
        (["--attempts_per_demo", "0"], "--attempts_per_demo must be a positive integer"),
    ):
        with pytest.raises(DataError, match=needle):
            parse_with(augment_demos, argv)


def test_minus_zero_sigma_is_one_line_in_every_command(tmp_path):
    """Issue 42 #4: -0.0 passed `v < 0`, then numpy's sampler refused it as a negative scale (a traceback
    from the engine, tracebacks from the lesson's and the lab's workers): one line, exit 2, nothing made."""
    for script, *extra in (
        ("augment_demos.py", "--src", tmp_path / "absent"),
        ("scale_data.py", "--smoke"),
        ("scale_lab.py", "--smoke"),
    ):
        for flag in ("--aug_pos_sigma", "--yaw_sigma"):
            p = run_script(script, *extra, flag, "-0.0", "--out", tmp_path / "o", check=False)
            err = p.stderr.strip().splitlines()
            assert p.returncode == 2 and len(err) == 1, (script, flag, p.stderr[-2000:])
            assert err[0] == f"error: {flag} must be a finite non-negative number, got -0.0", err
    assert not (tmp_path / "o").exists()


DISAGREE = [
    (augment_demos, "--per_demo", "2", "--attempts_per_demo", "3"),
    (augment_demos, "--mode", "replay", "--aug_mode", "resolve"),
    (augment_demos, "--pos_sigma", "0.01", "--aug_pos_sigma", "0.02"),
    (scale_lab, "--aug_yaw_sigma", "0.1", "--yaw_sigma", "0.2"),
    (lerobot_eval, "--episodes", "3", "--eval_episodes", "4"),
]


@pytest.mark.parametrize("mod,s1,v1,s2,v2", DISAGREE, ids=[f"{c[1]}-{c[3]}" for c in DISAGREE])
def test_an_old_and_a_new_spelling_that_disagree_are_refused(mod, s1, v1, s2, v2):
    """Issue 42 #12: both spellings of one flag with different values were accepted, the last one winning
    silently; refused in one line naming both. The same value under both spellings is that value."""
    for argv in ([s1, v1, s2, v2], [f"{s1}={v1}", s2, v2]):
        with pytest.raises(DataError) as e:
            parse_with(mod, argv)
        assert str(e.value).startswith(f"{s1} {v1} and {s2} {v2} are one flag"), str(e.value)
        assert "\n" not in str(e.value)
    assert parse_with(mod, [s1, v1, s2, v1]) == parse_with(mod, [s2, v1])


def test_a_shared_knob_has_one_name_default_and_bound_in_every_command():
    """A command takes a shared knob from its group (the very field, not a copy with its own default or
    bound); a name used by several commands has the same bound in each; and no command
    declares as its own name what another accepts only as an old spelling (--pos_sigma beside
    --aug_pos_sigma)."""
    group_fields = {f.name: (g, f) for g in GROUPS for f in config.fields(g)}
    assert set(group_fields) >= {
        "aug_pos_sigma",
        "aug_yaw_sigma",
        "aug_mode",
        "epochs",
        "lr",
        "workers",
        "ray",
    }
    for mod in COMMANDS:
        for f in config.fields(mod.Args):
            if f.name in group_fields:
                g, gf = group_fields[f.name]
                assert issubclass(mod.Args, g) and f is gf, (
                    f"{mod.__name__} re-declares --{f.name} of {g.__name__}"
                )
    # the lesson declares its own knobs where a reader meets them (issue 60 #5), the shared ones as
    # exact copies of their group's field: the same default, bound, range and old spellings
    own, _ = lesson_fields()
    for name in set(own) & set(group_fields):
        f = group_fields[name][1]
        assert own[name] == meta(f) | {"default": f.default}, f"scale_data.py: --{name} differs from config"
    every = commands()
    names = {n for fields in every.values() for n in fields}
    for name in names:
        seen = {cmd: fields[name] for cmd, fields in every.items() if name in fields}
        bounds = {(m["bound"], m["at_most"]) for m in seen.values()}
        assert len(bounds) == 1, f"--{name} has different bounds in different commands: {seen}"
    aliases = {a for fields in every.values() for m in fields.values() for a in m["aliases"]}
    assert not (aliases & names) - TWO_KNOBS, f"an old spelling is another command's flag: {aliases & names}"
    # the perturbation and the recipe are one definition in the lesson, the engine and the lab
    for knob in ("aug_pos_sigma", "aug_yaw_sigma"):
        assert {c for c in every if knob in every[c]} == {"scale_data", "augment_demos", "scale_lab"}
    for knob in ("epochs", "batch_size", "lr", "hidden_dim"):
        assert {c for c in every if knob in every[c]} == {"scale_data", "scale_lab"}


def test_the_lessons_flags_default_to_chapter():
    """Issue 60 #5: scale_data.py declares the chapter's flags itself (unit and why beside the lesson);
    CHAPTER, the defaults the tools and the exercises read, holds the same values, and the lesson takes
    no flag from config but the engine's and the plumbing's."""
    own, bases = lesson_fields()
    assert {b.__name__ for b in bases} == {"Mode", "Tries", "Parallel"}
    chapter = dataclasses.asdict(config.CHAPTER)
    wrong = {n: (own[n]["default"], v) for n, v in chapter.items() if n in own and own[n]["default"] != v}
    assert not wrong, f"scale_data.py's default differs from config.CHAPTER's (lesson, CHAPTER): {wrong}"
    assert set(chapter) - set(own) == {"aug_tries"}  # the engine's, from config.Tries


def test_per_demo_has_one_meaning():
    """augment_demos' attempts per source episode is --attempts_per_demo (old --per_demo) and reaches the
    engine as attempts_per_demo; only a run's stamps keep its first key, "per_demo", for the same bytes."""
    a = parse_with(augment_demos, ["--per_demo", "3", "--pos_sigma", "0.05", "--mode", "replay"])
    s = augment_demos.settings(a)
    assert s.attempts_per_demo == 3 and s.pos_sigma == 0.05 and s.mode == "replay"
    stored = s.stored()
    assert (
        stored["per_demo"] == 3
        and "attempts_per_demo" not in stored
        and set(stored) == {"mode", "select", "per_demo", "seed", "pos_sigma", "yaw_sigma", "shard_size"}
    )
    with pytest.raises(dataclasses.FrozenInstanceError):  # one object from the command line down: read only
        s.mode = "resolve"
    assert "per_demo" not in config.DEFAULTS  # the lesson's kept count is aug_per_demo
    assert config.CHAPTER.aug_per_demo == 8


def test_a_new_field_is_a_flag_with_its_default_bound_and_help():
    """Adding a flag is one field: the parser, the check and --help all read it."""

    @dataclasses.dataclass(frozen=True)
    class Args(config.Recipe):
        """a command"""

        widgets: int = config.flag(3, "widgets per gadget, why 3", bound=config.POSITIVE, at_most=9)
        fraction: float = config.flag(0.5, "of a gadget", bound=config.FINITE, aliases=("frac",))

    assert config.parse(Args, []).widgets == 3 and config.parse(Args, ["--frac", "0.2"]).fraction == 0.2
    for argv, needle in (
        (["--widgets", "0"], "--widgets must be a positive integer, got 0"),
        (["--widgets", "10"], "--widgets must be at most 9, got 10"),
        (["--frac", "nan"], "--frac must be a finite non-negative number, got nan"),
        (["--lr", "0"], "--lr must be a finite positive number, got 0.0"),
    ):
        with pytest.raises(DataError, match=needle):
            config.parse(Args, argv)
    text = config.parser_of(Args, "cmd").format_help()
    assert "widgets per gadget, why 3 (default: 3)" in " ".join(text.split())
    assert "--fraction FRACTION, --frac FRACTION" in text and "the BC training recipe" in text
    assert math.isclose(config.parse(Args, []).lr, config.CHAPTER.lr)


def test_supports_flag_reads_a_dataclass_field(tmp_path):
    from tools.common import supports_flag

    script = tmp_path / "s.py"
    script.write_text('class Args:\n    cache: bool = flag(True, "reuse")\n')
    assert supports_flag(script, "--cache") and not supports_flag(script, "--rerun")
    script.write_text('flag("--rerun", action=on_off)\n')  # a script from before the dataclasses
    assert supports_flag(script, "--rerun") and not supports_flag(script, "--cache")
    assert supports_flag(Path(ROOT / "scale_data.py"), "--cache")


def test_the_copies_kept_for_an_instant_help_match_their_sources():
    """--help and flag errors come before any heavy import (MuJoCo), so a few values are copied beside
    the flags; each copy must equal what it copies."""
    import aloha_env
    import datagen
    import pusht_env
    from ch37 import cli
    from datagen import engine
    from datagen.task import modes_of

    # every mode a task has is a --aug_mode choice (a task without an expert only replays)
    assert all(set(modes_of(t)) <= set(config.MODES) for t in datagen.known_tasks().values())
    assert modes_of(datagen.PUSHT) == config.MODES
    assert augment_demos.Args.__dataclass_fields__["select"].metadata["kw"]["choices"] == engine.SELECTS
    assert (cli.PUSHT_MAX_STEPS, cli.ALOHA_MAX_STEPS) == (pusht_env.MAX_STEPS, aloha_env.MAX_STEPS)
    assert (cli.PUSHT_OBS_DIM, cli.PUSHT_ACT_DIM) == (
        pusht_env.OBS_DIM,
        pusht_env.ACT_DIM,
    )  # the step probe's


def _flag_help(text: str, name: str) -> str:
    """The help of flag --NAME in a --help text, on one line."""
    lines = text.splitlines()
    start = next(i for i, s in enumerate(lines) if s.lstrip().startswith(f"--{name}"))
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("-")), len(lines))
    return " ".join(" ".join(lines[start:end]).split())


def test_gen_demos_help_needs_no_task_lists_the_tasks_and_their_units():
    """Issue 48 #6: `gen_demos.py --help` answered "error: no --task ..."; --task was in no usage text,
    and --noise said m/s where gym-pusht's noise is in px. Help works without a task and lists the tasks,
    and every unit is the task's own."""
    from datagen import known_tasks

    tasks = {n: t for n, t in known_tasks().items() if t.expert is not None}
    r = run_script(ROOT / "gen_demos.py", "--help", check=False)
    assert r.returncode == 0 and r.stderr == "" and "--task" in r.stdout.split("\n\n")[0], r.stdout + r.stderr
    task_help = _flag_help(r.stdout, "task")
    assert all(name in task_help for name in tasks), task_help
    noise = _flag_help(r.stdout, "noise")
    assert "gym_pusht px" in noise and "pusht m/s" in noise, noise
    r = run_script(ROOT / "gen_demos.py", "--task", "gym_pusht", "--help")
    assert "--task" in r.stdout.split("\n\n")[0] and "m/s" not in _flag_help(r.stdout, "noise"), r.stdout
    assert "px" in _flag_help(r.stdout, "noise") and "outputs/demos/gym_pusht" in r.stdout
    r = run_script(ROOT / "gen_demos_pusht.py", "--help")
    assert "--task" not in r.stdout and "m/s" in _flag_help(r.stdout, "noise"), r.stdout
