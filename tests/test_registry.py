"""A task registers itself when its module is imported, and the digests that guard resumed shards
(datagen.run.engine_version) and cached demo sets (datagen.demos.generator_version) are read from
the modules a task imports (ch37.code_files), so no list of files can forget a task's code."""

import json
import sys
import types
from pathlib import Path

import pytest
from conftest import run_script

import datagen
import pusht_env
from datagen import ALOHA, PUSHT, demos, run
from datagen.task import EnvSpec, known_tasks, register


def test_every_task_module_registers_itself_and_no_list_names_them():
    """Our tasks are known by their names, each from its own module of datagen/; a user's task module
    registered beside them is allowed (test_the_suite_passes_with_a_users_task_registered)."""
    from datagen.tasks.gym_pusht import GYM_PUSHT

    known = known_tasks()
    assert {n: known[n] for n in ("aloha", "gym_pusht", "pusht")} == {
        "aloha": ALOHA,
        "gym_pusht": GYM_PUSHT,
        "pusht": PUSHT,
    }
    assert all(type(t).__module__.startswith("datagen.") and t.name == n for n, t in known.items())
    assert not hasattr(datagen, "TASKS")
    assert register(PUSHT) is PUSHT  # registering again is harmless


def _edited(monkeypatch, target: Path) -> None:
    """Every read of `target` from now on sees it with one more line (an edit of its source)."""
    real = Path.read_bytes
    target = target.resolve()
    monkeypatch.setattr(
        Path, "read_bytes", lambda self: real(self) + (b"\n# edited\n" if self.resolve() == target else b"")
    )


@pytest.mark.parametrize("name", ["pusht", "aloha"])
def test_an_edit_to_a_task_module_its_env_or_its_expert_changes_the_digests(monkeypatch, name):
    task = known_tasks()[name]
    expert = task.expert.cls
    module = sys.modules[type(task).__module__]
    env = sys.modules[f"{name}_env"]  # pusht_env, aloha_env
    digest_run = lambda: run.engine_version(task)  # noqa: E731
    digest_demos = lambda: demos.generator_version.__wrapped__(task)  # noqa: E731
    before = digest_run(), digest_demos()
    for f, guards_demos in (
        (module.__file__, True),  # the task module: a demo set is made through it (its env, its expert)
        (env.__file__, True),  # the env the task module imports
        (env.XML_PATH, True),
        (sys.modules[expert.__module__].__file__, True),
    ):
        with monkeypatch.context() as m:
            _edited(m, Path(f))
            assert digest_run() != before[0], f"an edit of {f} leaves the {name} run digest as it was"
            if guards_demos:
                assert digest_demos() != before[1], f"an edit of {f} leaves the {name} demo digest as it was"
    assert (digest_run(), digest_demos()) == before


@pytest.mark.parametrize("step", ["run", "source_check", "plan", "resume", "shards", "report"])
def test_an_edit_to_any_step_of_a_run_changes_the_run_digest(monkeypatch, step):
    """The run is cut by job into modules (datagen.run orders them); its digest is read from what
    datagen.run imports, so each of them guards resumed shards without being listed."""
    digest_run = lambda: run.engine_version(PUSHT)  # noqa: E731
    before = digest_run()
    _edited(monkeypatch, Path(sys.modules[f"datagen.{step}"].__file__))
    assert digest_run() != before, f"an edit of datagen/{step}.py leaves the run digest as it was"


def _copy_with(tmp_path: Path, name: str, text: str) -> Path:
    """A copy of the project's code with one more module datagen/tasks/NAME (the repository is never
    written)."""
    import shutil

    root = Path(__file__).resolve().parent.parent
    skip = shutil.ignore_patterns(
        ".git", ".venv", "outputs", "__pycache__", ".*_cache", "tests", "docs", "results"
    )
    copy = tmp_path / "project"
    shutil.copytree(root, copy, ignore=skip)
    (copy / "datagen" / "tasks" / name).write_text(text)
    return copy


def _run(copy: Path, *argv):
    return run_script(*argv, cwd=copy, check=False, timeout=300)


def test_a_copied_task_module_is_one_warning_naming_both_modules_and_every_command_works(tmp_path):
    """Issue 48 #7: copying datagen/tasks/pusht.py to datagen/my_task.py (a newcomer's first step of adding a
    task) stopped every engine command with "ValueError: two tasks named 'pusht': PushT and PushT",
    naming no file. Now one warning line names both modules; the commands go on with the tasks known."""
    copy = _copy_with(
        tmp_path, "my_task.py", (Path(datagen.__file__).parent / "tasks" / "pusht.py").read_text()
    )
    r = _run(copy, "gen_demos.py", "--task", "pusht", "--episodes", "1", "--quiet", "--out", tmp_path / "s")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 0 and len(err) == 1 and err[0].startswith("warning: "), r.stderr
    assert (
        "datagen/tasks/my_task.py" in err[0] and "datagen/tasks/pusht.py" in err[0] and "'pusht'" in err[0]
    ), err
    args = ["--src", tmp_path / "s", "--out", tmp_path / "grown", "--per_demo", "1", "--workers", "1"]
    r = _run(copy, "augment_demos.py", *args, "--quiet")
    assert r.returncode == 0 and r.stderr.strip().splitlines() == err, r.stderr


def test_a_task_module_that_fails_to_import_makes_only_its_own_task_unavailable(tmp_path):
    """Issue 48 #7: a task module that raised on import stopped augment_demos.py and gen_demos.py for every
    task, PushT sets included, with its traceback. Now it is one warning line naming it and why; every
    other task works, and asking for its task is one error line."""
    copy = _copy_with(tmp_path, "half_done.py", "import numpy\n\nraise RuntimeError('not finished yet')\n")
    r = _run(copy, "gen_demos.py", "--task", "pusht", "--episodes", "1", "--quiet", "--out", tmp_path / "s")
    err = r.stderr.strip().splitlines()
    assert r.returncode == 0 and len(err) == 1 and err[0].startswith("warning: "), r.stderr
    assert "datagen/tasks/half_done.py" in err[0] and "RuntimeError: not finished yet" in err[0], err
    args = ["--src", tmp_path / "s", "--out", tmp_path / "grown", "--per_demo", "1", "--workers", "1"]
    r = _run(copy, "augment_demos.py", *args, "--quiet")
    assert r.returncode == 0 and r.stderr.strip().splitlines() == err, r.stderr
    r = _run(copy, "gen_demos.py", "--task", "half_done", "--out", tmp_path / "x")
    assert r.returncode == 2 and r.stderr.strip().splitlines()[:-1] == err, r.stderr
    assert r.stderr.strip().splitlines()[-1].startswith("error: --task 'half_done'"), r.stderr
    assert not (tmp_path / "x").exists() and "Traceback" not in r.stderr


def test_the_contract_is_small_and_a_task_that_breaks_it_is_refused_in_one_line():
    """Issues 46 and 58 #4: Task is an abstract base read in one sitting (at most 20 public names, at most
    8 of them required; MimicGen's has six methods), its settings in three typed groups (spec, replay,
    expert); a class missing a required method cannot be made, one missing a required attribute, giving
    a group of the wrong type or a subtask no frame for one of its arms is refused at registration, each
    in one line that names what is wrong."""
    from datagen.task import REQUIRED_ATTRIBUTES, Subtask, Task, contract_problem, modes_of
    from datagen.tasks.pusht import PushT

    public = {n for n in (*vars(Task), *Task.__annotations__) if not n.startswith("_")}
    assert len(public) <= 20, sorted(public)
    required = set(Task.__abstractmethods__) | set(REQUIRED_ATTRIBUTES)
    assert required == set(Task.__abstractmethods__) | {
        a for a in Task.__annotations__ if a not in vars(Task)
    }
    assert len(required) <= 8, sorted(required)

    class NoPose(PushT):
        object_pose = Task.object_pose  # the abstract one: not written yet

    with pytest.raises(TypeError, match="abstract method 'object_pose'"):
        NoPose()

    # a task written from scratch that never says its name: PushT's methods, its other attributes
    parts = {m: getattr(PushT, m) for m in Task.__abstractmethods__}
    parts |= {a: getattr(PushT, a) for a in REQUIRED_ATTRIBUTES if a != "name"} | {"__module__": __name__}
    with pytest.raises(TypeError) as e:
        register(type("NoName", (Task,), parts)())
    assert len(str(e.value).splitlines()) == 1 and "misses the required attribute name" in str(e.value)
    assert "test_registry.py: NoName" in str(e.value), str(e.value)

    class LooseSpec(PushT):  # the env's constants as a plain module, not the typed spec
        spec = pusht_env

    with pytest.raises(TypeError) as e:
        register(LooseSpec())
    assert len(str(e.value).splitlines()) == 1 and "has a spec of type module: give an EnvSpec" in str(
        e.value
    )

    class LooseReplay(PushT):  # the replay settings as a plain dict, not the typed spec
        replay = {"arms": PushT.replay.arms, "action": PushT.replay.action}

    with pytest.raises(TypeError) as e:
        register(LooseReplay())
    assert len(
        str(e.value).splitlines()
    ) == 1 and "has a replay of type dict: give a ReplaySpec or None" in str(e.value)
    only_resolves = type("OnlyResolves", (PushT,), {"name": "only_resolves", "replay": None})()
    assert contract_problem(only_resolves) is None and modes_of(only_resolves) == ("resolve",)
    with pytest.raises(TypeError, match="pusht_env has no MAX_STEPS"):
        EnvSpec.of(
            types.SimpleNamespace(**{k: getattr(pusht_env, k) for k in dir(pusht_env) if k != "MAX_STEPS"})
        )

    two_arms = PushT(subtasks=(Subtask("push", ("block", "block")),))
    with pytest.raises(
        TypeError, match="subtask 'push' with 2 frame.s. for 1 arm.s. .pusher.: give each arm"
    ):
        register(two_arms)
    assert known_tasks()["pusht"] is PUSHT


USER_TASK = """\"\"\"A user's task: PushT with a tighter reach, beside ours (no list names it).\"\"\"

from dataclasses import replace

from datagen.tasks.pusht import PushT
from datagen.task import register


class MyPushT(PushT):
    name = "my_pusht"
    title = "my PushT"
    replay = replace(PushT.replay, reach={"pusher": ((-0.3, 0.3), (-0.3, 0.3))})


MY_PUSHT = register(MyPushT())
"""


def test_the_suite_passes_with_a_users_task_registered(tmp_path):
    """Issue 46: adding a task made the registry test fail (it asserted known_tasks() was exactly ours).
    With a user's task module in datagen/, the tests that read the registry pass in a copy of the
    project, and the user's task is known to the commands."""
    import shutil

    copy = _copy_with(tmp_path, "my_pusht.py", USER_TASK)
    shutil.copytree(Path(__file__).resolve().parent, copy / "tests")
    r = _run(copy, "gen_demos.py", "--help")
    assert r.returncode == 0 and "my_pusht" in r.stdout, r.stdout + r.stderr
    tests = ["tests/test_registry.py", "tests/test_flags.py", "tests/test_hidden_state.py"]
    # the tests that copy the project themselves, each a minute of subprocesses, are not run again in it
    skip = "not copied_task_module and not fails_to_import and not users_task and not sets_name_their_task"
    skip += " and not returns_nan"
    r = run_script(
        "-m", "pytest", "-q", "-p", "no:cacheprovider", *tests, "-k", skip, cwd=copy, check=False, timeout=600
    )
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]


def test_sets_name_their_task_so_a_users_variant_and_ours_each_grow_their_own(tmp_path):
    """Issue 58 #1: the task of a set was guessed from its robot_type and widths, so with a user's variant
    of PushT registered (same robot, same widths) every PushT set "fit no task of the engine". Now every
    set the project writes names its task (meta/engine_task.json), and augment_demos.py grows it as that
    task: ours as PushT, the variant's as the variant (two tasks of one robot with equal widths). A set
    written elsewhere that fits both is one error line naming them, and --task chooses."""
    import shutil

    from datagen.demos import TASK_FILE
    from datagen.report import REPORT_NAME

    copy = _copy_with(tmp_path, "my_pusht.py", USER_TASK)
    grown = {}
    for name in ("pusht", "my_pusht"):
        src, out = tmp_path / f"src_{name}", tmp_path / f"grown_{name}"
        r = _run(copy, "gen_demos.py", "--task", name, "--episodes", "1", "--quiet", "--out", src)
        assert r.returncode == 0, r.stderr
        assert json.loads((src / TASK_FILE).read_text()) == {"task": name}
        r = _run(copy, "augment_demos.py", "--src", src, "--out", out, "--per_demo", "1", "--workers", "1")
        assert r.returncode == 0, r.stdout + r.stderr
        grown[name] = json.loads((out / REPORT_NAME).read_text())
        assert json.loads((out / TASK_FILE).read_text()) == {"task": name}  # the grown set names it too
    assert {name: report["task"] for name, report in grown.items()} == {n: n for n in grown}

    elsewhere = tmp_path / "elsewhere"  # the same frames as a set written by another program
    shutil.copytree(tmp_path / "src_pusht", elsewhere)
    for extra in (TASK_FILE, "scale_data_stamp.json"):
        (elsewhere / extra).unlink()
    r = _run(copy, "augment_demos.py", "--src", elsewhere, "--out", tmp_path / "g1", "--per_demo", "1")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert "my_pusht, pusht" in lines[0] and "--task" in lines[0], lines
    args = [
        "--src",
        elsewhere,
        "--out",
        tmp_path / "g2",
        "--per_demo",
        "1",
        "--workers",
        "1",
        "--task",
        "pusht",
    ]
    assert _run(copy, "augment_demos.py", *args).returncode == 0
    r = _run(copy, "augment_demos.py", *args[:3], tmp_path / "g3", "--task", "nope")
    assert r.returncode == 2 and "--task 'nope' is no task of the engine" in r.stderr, r.stderr


NAN_TASK = """\"\"\"A user's task whose perturb returns a NaN (issue 62 #1).\"\"\"

from datagen.task import register
from datagen.tasks.pusht import PushT


class NanPushT(PushT):
    name = "nan_pusht"

    def perturb(self, first_state, rng, how):
        return (float("nan"),) + tuple(PushT.perturb(self, first_state, rng, how))[1:]


NAN_PUSHT = register(NanPushT())
"""


def test_a_users_task_that_returns_nan_is_one_line_from_the_workers_and_nothing_is_written(tmp_path):
    """Issue 62 #1: augment_demos.py grew a task whose perturb returned a NaN ("4 kept", non-finite
    aug.start, actions and states in the set). Run by worker processes, it is now one error line naming
    the member, exit 2, and no set is written."""
    copy = _copy_with(tmp_path, "nan_pusht.py", NAN_TASK)
    src, out = tmp_path / "s", tmp_path / "grown"
    assert (
        _run(copy, "gen_demos.py", "--task", "pusht", "--episodes", "2", "--quiet", "--out", src).returncode
        == 0
    )
    args = ["--src", src, "--out", out, "--per_demo", "2", "--workers", "2", "--task", "nan_pusht", "--quiet"]
    r = _run(copy, "augment_demos.py", *args)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), r.stderr
    assert "NanPushT.perturb returned a non-finite number" in lines[0], lines
    assert not (out / "data").exists() and "Traceback" not in r.stderr
