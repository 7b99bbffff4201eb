"""The plumbing and presentation of chapter 3.7: what scale_data.py imports but does not teach, one
concern per module. The LeRobot v3 format is the package lerobot_v3; the data engine and the demo sets
are datagen. ch37 is the floor: none of its modules imports either.

plumbing (imported by the engine, the format's error type included, and the tools)
  errors        DataError, guard() / run_main() / main(): one line and an exit code (2, 130 on Ctrl-C)
  ownership     claim(): an output folder checked up front, locked, owned file by file (the Claim passed
                to every write); stamps; write_atomic, publish_dir, dump_json, read_json: whole or none
  process       process hygiene: workers die with the run, stop signals around a fork, core and memory limits
  parallel      map_jobs: the one map over jobs (forked processes or Ray); LockstepEnvs for evaluation;
                step_envs: a batch of envs stepped (theirs and the engine's lanes)
  seeds         env_seed: demos, augmentation and evaluation never share a start
  ensemble      several MLPs as one module: the arms of a training budget side by side
presentation and flags (the lesson's and the tools'; never imported by datagen or lerobot_v3)
  config        the chapter's defaults and smoke settings, the one flag parser and checker
  cli           scale_data.py's flag limits, claim_out, device choice, the tier banner, the five-seed
                reference a run is placed beside
  result_cache  reuse a finished run whose flags and code match; entries verified by checksum
  viz           the PNG figures and the Rerun recordings (the chapter's and the Scale Lab's)
  poster        the self-contained HTML posters (scale_data.html, scale_lab.html): inline SVG, no script

A command of its own (the data engine, a tool) gets the same guarantees from errors.run_main,
ownership.claim (or ownership.check_out_path), ownership.replace_own_dir and process.worker_setup.
"""

import hashlib
import inspect
import sys
import warnings
from pathlib import Path

# In Jupyter without ipywidgets, tqdm.auto (which the datasets library imports) warns once and uses
# the text progress bar instead of a widget: the notebook loses nothing, so the warning is noise.
warnings.filterwarnings("ignore", message="IProgress not found")

ROOT = Path(__file__).resolve().parent.parent  # the repository root: scale_data.py, the envs, meta.yaml
CHAPTER_ID = "ch3.7-scale-data"
__all__ = [  # the face: the modules above, and the repository's root and code lists
    "cli",
    "config",
    "ensemble",
    "errors",
    "ownership",
    "parallel",
    "poster",
    "process",
    "result_cache",
    "seeds",
    "viz",
    "CHAPTER_ID",
    "ROOT",
    "code_digest",
    "code_files",
]

SKIP = (".venv", "tests", "outputs")  # under ROOT, never the code of a result


def _ours(f) -> str | None:
    """The path from ROOT of a project file (SKIP aside), else None."""
    p = Path(f).resolve() if isinstance(f, (str, Path)) else None
    if p and p.is_file() and p.is_relative_to(ROOT) and p.relative_to(ROOT).parts[0] not in SKIP:
        return p.relative_to(ROOT).as_posix()
    return None


def _imported_by(module) -> list:
    """The modules `module` uses, read from its namespace: the modules it holds and the modules its
    functions and classes come from. A package's own submodules are not followed: which of them are
    attributes of it depends on what else this process imported."""
    out, pkg = [], getattr(module, "__name__", "") + "."
    for v in list(vars(module).values()):
        if inspect.ismodule(v):
            if not v.__name__.startswith(pkg):
                out.append(v)
        elif isinstance(getattr(v, "__module__", None), str):  # a function, a class, an instance
            m = sys.modules.get(v.__module__)
            if m is not None:
                out.append(m)
    return out


def code_files(roots=None) -> dict[str, str]:
    """{path from ROOT: sha256} of the project code loaded in this process, the one home of "the code
    a result depends on", read from what was imported, never from a list kept by hand.

    roots None: the file of every imported module under the repository (its virtualenv and tests aside):
    the result cache's record of what a run imported (ch37.result_cache). roots (modules): those modules
    and every project module they import, transitively (_imported_by), so the same roots give the same
    files whatever else the process imported: a demo set's digest (datagen.demos.generator_version: the
    task's env and expert) and a run's (datagen.run.engine_version: the engine and the task module).
    Each module brings its file, the model file it names (XML_PATH) and the files it says it reads (READS).
    """
    if roots is None:
        modules = [m for m in list(sys.modules.values()) if _ours(getattr(m, "__file__", None))]
    else:
        modules, todo = [], list(roots)
        seen = set()
        while todo:
            m = todo.pop()
            if id(m) in seen or not _ours(getattr(m, "__file__", None)):
                continue
            seen.add(id(m))
            modules.append(m)
            todo += _imported_by(m)
    found = set()
    for module in modules:  # only our modules are asked what they read
        named = (module.__dict__.get("XML_PATH"), *module.__dict__.get("READS", ()))
        found |= {_ours(module.__file__)} | {f for f in map(_ours, named) if f}
    return {rel: hashlib.sha256((ROOT / rel).read_bytes()).hexdigest() for rel in sorted(found)}


def code_digest(roots) -> str:
    """First 12 hex of sha256 over code_files(roots): the modules `roots` and what they import."""
    h = hashlib.sha256()
    for rel, digest in code_files(roots).items():
        h.update(f"{rel}\0{digest}\n".encode())
    return h.hexdigest()[:12]
