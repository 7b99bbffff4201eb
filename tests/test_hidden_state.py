"""Issue 39 #4, hidden state made visible, read from the code (ast, nothing imported): importing a module
of ours sets no environment variable and patches no function of another library; a patch made while a
call needs it is put back in that call's `finally`; and every LeRobot, datasets or huggingface_hub import
of ours comes after lerobot_v3.hub_offline (any of them imports huggingface_hub, which reads its offline
switch once).

A command's own main flow may set its process's environment: a program's `if __name__ == "__main__":`
block (the demo generators choose MuJoCo's GL backend there), and scale_data.py, the lesson, which is
a script from its first line (its setup region holds the kernel path before numpy and torch load).
"""

import ast
import sys

import pytest
from test_package_layering import MODULES, ROOT

ENVIRON_CALLS = {"setdefault", "update", "pop", "popitem", "clear", "__setitem__", "__delitem__"}
SCRIPT = {  # a script whose module level is its main flow: the one environment write it makes
    "scale_data": {"os.environ.update(cli.kernel_path())"}
}
HF = ("lerobot", "datasets", "huggingface_hub")
OFFLINE_FIRST = {"hub_offline", "check_hf_cache", "_lerobot_dataset_class"}  # each starts with hub_offline


def is_environ(node) -> bool:
    return (
        isinstance(node, ast.Attribute)
        and node.attr == "environ"
        and isinstance(node.value, ast.Name)
        and node.value.id == "os"
    )


def is_main_guard(node) -> bool:
    return (
        isinstance(node, ast.If)
        and "__main__" in ast.unparse(node.test)
        and "__name__" in ast.unparse(node.test)
    )


def import_time(tree: ast.Module):
    """Every node that runs when the module is imported: its body, less function and class bodies
    (a decorator or a default value runs, but sets nothing here) and the main guard."""
    todo = list(tree.body)
    while todo:
        node = todo.pop()
        if isinstance(
            node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef | ast.Lambda
        ) or is_main_guard(node):
            continue
        yield node
        todo.extend(ast.iter_child_nodes(node))


def environment_writes(nodes) -> list[tuple[int, str]]:
    """(line, the statement) for each write to os.environ (or os.putenv / os.unsetenv) among `nodes`."""
    found = []
    for node in nodes:
        target = None
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            f = node.func
            if is_environ(f.value) and f.attr in ENVIRON_CALLS:
                target = node
            elif isinstance(f.value, ast.Name) and f.value.id == "os" and f.attr in ("putenv", "unsetenv"):
                target = node
        elif isinstance(node, ast.Assign | ast.AugAssign | ast.Delete):
            targets = node.targets if isinstance(node, ast.Assign | ast.Delete) else [node.target]
            if any(isinstance(t, ast.Subscript) and is_environ(t.value) for t in targets):
                target = node
        if target is not None:
            found.append((node.lineno, ast.unparse(target)))
    return found


def third_party_aliases(tree: ast.Module) -> set[str]:
    """Names bound to another library's module or object by an import anywhere in the file (Python's own
    aside: a command's main sets sys.argv or sys.excepthook for its process, ch37.errors.guard)."""
    ours = {name.split(".")[0] for name in MODULES} | set(sys.stdlib_module_names)
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {
                a.asname or a.name.split(".")[0] for a in node.names if a.name.split(".")[0] not in ours
            }
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] not in ours:
                names |= {a.asname or a.name for a in node.names}
    return names


def patched(nodes, aliases: set[str]) -> list[ast.Assign]:
    """The assignments among `nodes` to an attribute of another library's module: `module.name = ...`."""
    return [
        node
        for node in nodes
        if isinstance(node, ast.Assign)
        and any(
            isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) and t.value.id in aliases
            for t in node.targets
        )
    ]


@pytest.mark.parametrize("name", sorted(MODULES))
def test_importing_a_module_sets_no_environment_variable(name):
    writes = environment_writes(import_time(ast.parse(MODULES[name].read_text())))
    allowed = SCRIPT.get(name, set())
    writes = [(line, s) for line, s in writes if s not in allowed]
    assert not writes, f"{MODULES[name].relative_to(ROOT)} sets at import: {writes}"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_other_library_is_patched_at_import_and_a_patch_is_put_back(name):
    tree = ast.parse(MODULES[name].read_text())
    aliases = third_party_aliases(tree)
    at_import = patched(import_time(tree), aliases)
    assert not at_import, [
        f"{MODULES[name].relative_to(ROOT)}:{n.lineno} {ast.unparse(n)}" for n in at_import
    ]
    for fn in [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)]:
        put_back = {
            ast.unparse(t)
            for node in ast.walk(fn)
            if isinstance(node, ast.Try)
            for stmt in node.finalbody
            for assign in patched(ast.walk(stmt), aliases)
            for t in assign.targets
        }
        for node in patched(ast.walk(fn), aliases):
            for t in node.targets:
                where = f"{MODULES[name].relative_to(ROOT)}:{node.lineno} {fn.name}"
                assert ast.unparse(t) in put_back, f"{where} patches {ast.unparse(t)} without putting it back"


def test_the_check_finds_what_it_looks_for():
    """The detectors above, on code that breaks each rule (a check that finds nothing proves nothing)."""
    bad = ast.parse(
        "import os\nimport tqdm\nos.environ['X'] = '1'\nos.environ.setdefault('Y', '1')\n"
        "tqdm.tqdm = None\nif __name__ == '__main__':\n    os.environ['Z'] = '1'\n"
        "def f():\n    os.environ['W'] = '1'\n"
    )
    assert [line for line, _ in environment_writes(import_time(bad))] == [4, 3]
    assert [n.lineno for n in patched(import_time(bad), third_party_aliases(bad))] == [5]
    assert not offline_first_problems(ast.parse("def f():\n    hub_offline()\n    import datasets\n"))
    assert offline_first_problems(ast.parse("def f():\n    import datasets\n    hub_offline()\n"))
    assert offline_first_problems(ast.parse("import lerobot.datasets\n"))


def offline_first_problems(tree: ast.Module) -> list[str]:
    """Each LeRobot, datasets or huggingface_hub import not preceded, in its function, by hub_offline (or
    a function of ours that starts with it); hub_offline's own imports aside. A module-level one is one."""
    problems = [
        f"{node.lineno}: at import"
        for node in tree.body
        if isinstance(node, ast.Import | ast.ImportFrom) and hf_import(node)
    ]
    for fn in [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef) and n.name != "hub_offline"]:
        own = own_nodes(fn)
        first = min(
            (n.lineno for n in own if isinstance(n, ast.Import | ast.ImportFrom) and hf_import(n)),
            default=None,
        )
        if first is None:
            continue
        calls = [
            n.lineno
            for n in own
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in OFFLINE_FIRST
        ]
        if not calls or min(calls) > first:
            problems.append(f"{first}: {fn.name} imports before hub_offline")
    return problems


def hf_import(node) -> bool:
    mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
    return node.__dict__.get("level", 0) == 0 and any(m.split(".")[0] in HF for m in mods)


def own_nodes(fn: ast.FunctionDef) -> list:
    """The nodes of `fn` itself, not of a function nested in it (which checks its own imports)."""
    out, todo = [], list(ast.iter_child_nodes(fn))
    while todo:
        node = todo.pop()
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            out.append(node)
            todo.extend(ast.iter_child_nodes(node))
    return out


@pytest.mark.parametrize("name", sorted(MODULES))
def test_lerobot_is_imported_offline(name):
    problems = offline_first_problems(ast.parse(MODULES[name].read_text()))
    assert not problems, f"{MODULES[name].relative_to(ROOT)}: {problems}"
