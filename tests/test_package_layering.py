"""The house's layering, read from the imports (ast, nothing imported): three packages with narrow
faces, and every arrow pointing down.

    lerobot_v3  the LeRobot v3 format: imports nothing of the project but the error type
    datagen     the data engine: imports the format and the chapter's plumbing, never its
                presentation or flag modules
    ch37        the chapter's plumbing and presentation
    the lesson  scale_data.py: imports package faces (__all__), never a private name

ch37 is the floor (none of its modules imports the format or the engine), the format above it, the
engine above both, the scripts and tools on top: every arrow points down or stays on its floor.

and nowhere does a module import a _private name from another package, or sit on an import cycle.
"""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("ch37", "lerobot_v3", "datagen")
TOP = (
    "scale_data",
    "scale_lab",
    "augment_demos",
    "bc_recipe",
    "gen_demos",
    "gen_demos_pusht",
    "gen_demos_aloha",
)
TOP += ("pusht_env", "aloha_env", "scripted_expert", "gym_envs")
# the chapter's presentation and flag modules: the engine and the format never reach them
PRESENTATION = {"ch37.cli", "ch37.config", "ch37.viz", "ch37.poster", "ch37.result_cache"}
# The engine's fast copies of code in the learner's files (issue 39: the learner's files stay plain),
# each bit for bit what it copies: a fast copy reads the very constants and state of what it copies (a
# number copied by hand could drift), through their public names, so it may import those modules.
FAST_COPIES = {
    "datagen.tasks.fast_experts": {"scripted_expert"},
    "datagen.tasks.fast_pusht": {"pusht_env"},
}
ERROR_TYPE = "ch37.errors"


def modules() -> dict[str, Path]:
    """{dotted name: file} of the project's own code (packages, root scripts, tools), tests aside."""
    found = {name: ROOT / f"{name}.py" for name in TOP}
    for pkg in (*PACKAGES, "tools", "exercises"):
        for path in sorted((ROOT / pkg).rglob("*.py")):  # and its subpackages (datagen/tasks)
            parts = path.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if path.stem == "__init__" else parts)] = path
    return found


MODULES = modules()


def package_of(name: str) -> str:
    return name.split(".")[0]


def imports(path: Path) -> list[tuple[str, str | None, int]]:
    """(module, imported name or None, line) for every import in `path`, at any depth (lazy ones too)."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, None, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out += [(node.module, a.name, node.lineno) for a in node.names]
    return out


def edges(name: str) -> set[str]:
    """The project modules `name` imports (`from pkg import mod` counts as pkg.mod)."""
    got = set()
    for mod, what, _ in imports(MODULES[name]):
        if what is not None and f"{mod}.{what}" in MODULES:
            got.add(f"{mod}.{what}")
        elif mod in MODULES:
            got.add(mod)
    return got - {name}


def faces(pkg: str) -> set[str]:
    """The names in a package's __all__ (read from its __init__.py)."""
    tree = ast.parse((ROOT / pkg / "__init__.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return set(ast.literal_eval(node.value))
    raise AssertionError(f"{pkg}/__init__.py has no __all__")


@pytest.mark.parametrize("pkg", PACKAGES)
def test_every_package_has_a_face(pkg):
    names = faces(pkg)
    assert names and all(not n.startswith("_") for n in names), names


def test_the_format_imports_nothing_of_ours_but_the_error_type():
    for name in [m for m in MODULES if package_of(m) == "lerobot_v3"]:
        ours = {m for m in edges(name) if package_of(m) != "lerobot_v3"}
        assert ours <= {ERROR_TYPE, "ch37"}, (name, ours)
        for mod, what, line in imports(MODULES[name]):
            if package_of(mod) == "ch37":
                assert mod == ERROR_TYPE and what == "DataError", (name, line, mod, what)


def test_the_engine_imports_the_format_and_no_presentation_or_flags():
    for name in [m for m in MODULES if package_of(m) == "datagen"]:
        reached = edges(name)
        assert not reached & PRESENTATION, (name, reached & PRESENTATION)
        assert not {m for m in reached if package_of(m) in ("tools", "scale_data", "augment_demos")}, name
    used = set().union(*(edges(m) for m in MODULES if package_of(m) == "datagen"))
    assert any(package_of(m) == "lerobot_v3" for m in used)


def task_modules() -> set[str]:
    """The engine's task modules, found as the engine finds them: a datagen module that registers a
    task (calls register(...), datagen.task.register) when imported. No list names them."""
    found = set()
    for name in [m for m in MODULES if package_of(m) == "datagen" and m != "datagen.task"]:
        for node in ast.walk(ast.parse(MODULES[name].read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "register":
                found.add(name)
    return found


def test_only_a_task_module_imports_its_env_and_expert():
    assert {"datagen.tasks.pusht", "datagen.tasks.aloha"} <= task_modules()  # the detection finds ours
    for name in [m for m in MODULES if package_of(m) == "datagen"]:
        envs = {m for m in edges(name) if m in ("pusht_env", "aloha_env", "scripted_expert")}
        assert not envs or name in (*task_modules(), *FAST_COPIES), (name, envs)


def test_the_lesson_imports_package_faces():
    for mod, what, line in imports(MODULES["scale_data"]):
        if package_of(mod) in ("lerobot_v3", "datagen"):
            assert mod in ("lerobot_v3", "datagen"), f"scale_data.py:{line} imports {mod}, not the face"
            assert what is None or what in faces(mod), f"scale_data.py:{line}: {what} is not in {mod}.__all__"
        assert what is None or not what.startswith("_"), f"scale_data.py:{line} imports {what}"


def test_nothing_imports_a_private_name_across_a_package():
    """The engine's fast copies included (issue 58: they read scripted_expert's and pusht_env's constants
    and state by public names now)."""
    for name, path in MODULES.items():
        for mod, what, line in imports(path):
            if mod.split(".")[0] not in (*PACKAGES, *TOP, "tools") or package_of(mod) == package_of(name):
                continue
            private = [p for p in [*mod.split(".")[1:], what or ""] if p.startswith("_") and p != "__init__"]
            assert not private, f"{path.relative_to(ROOT)}:{line} imports {mod}.{what}"
        # nor reaches one through a module it imported from another package: mod._name
        aliases = {}
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                for a in node.names:
                    if f"{node.module}.{a.name}" in MODULES and package_of(node.module) != package_of(name):
                        aliases[a.asname or a.name] = node.module
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name in MODULES and package_of(a.name) != package_of(name):
                        aliases[a.asname or a.name.split(".")[0]] = a.name
        for node in ast.walk(ast.parse(path.read_text())):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id in aliases
            ):
                private = node.attr.startswith("_") and not node.attr.startswith("__")
                assert not private, f"{path.relative_to(ROOT)}:{node.lineno} uses {node.value.id}.{node.attr}"


def test_no_import_cycles_and_no_arrow_back_up():
    rank = {"ch37": 0, "lerobot_v3": 1, "datagen": 2}  # the floor, the format, the engine; scripts above
    graph = {name: edges(name) for name in MODULES}
    for name, targets in graph.items():
        for t in targets:
            if package_of(name) == "lerobot_v3":
                assert package_of(t) == "lerobot_v3" or t in (ERROR_TYPE, "ch37"), (name, t)
            if package_of(t) in rank and package_of(name) in rank:
                assert rank[package_of(t)] <= rank[package_of(name)], f"{name} -> {t} runs back up"
            if package_of(name) in rank and package_of(t) not in rank:  # a package never reaches a script
                assert package_of(t) in ("pusht_env", "aloha_env", "scripted_expert"), f"{name} -> {t}"
                assert name.startswith("datagen."), f"{name} -> {t}: only a task module imports its env"
    state = {}

    def visit(n, path):
        state[n] = "open"
        for t in sorted(graph[n]):
            if state.get(t) == "open":
                raise AssertionError("import cycle: " + " -> ".join([*path, n, t]))
            if t not in state:
                visit(t, [*path, n])
        state[n] = "done"

    for n in sorted(graph):
        if n not in state:
            visit(n, [])
