"""Every command's flags, each declared once as a dataclass field, and the one flag checker.

A command's flags are one dataclass (CleanRL's `Args`), its fields made by flag(): default, help (unit
and why), bound and old spellings in one place, so adding a flag touches one file. The knobs several
commands share are groups declared here, and a command takes a group by inheriting it: Recipe (the BC
training recipe), Perturbation, Mode and Tries (the data engine's perturbation, mode and attempts),
Parallel and Ray (where the work runs). The lesson declares its own knobs in scale_data.py, where a
reader meets them, and takes the engine's and the plumbing's from here; CHAPTER holds its defaults for
the tools and exercises. So the same knob has the same name, default and bound in the lesson,
augment_demos.py and scale_lab.py (tests/test_flags.py). parse() builds the argparse parser from a
dataclass (each group an argument group, --help showing every flag's default) and checks the bounds:
every flag problem is one `error:` line and exit 2 (through ch37.errors), before any work.
Importing this module defines classes and does nothing else.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

from ch37.errors import DataError

# A flag's bound (flag(bound=...)), each with its one-line error (check() below):
POSITIVE = "positive"  # an integer > 0: "--NAME must be a positive integer, got V"
NON_NEGATIVE = "non_negative"  # >= 0: "--NAME must be >= 0, got V"
FINITE = "finite"  # a finite number >= 0, not -0.0: "--NAME must be a finite non-negative number, got V"
FINITE_POSITIVE = "finite_positive"  # a finite number > 0: "--NAME must be a finite positive number, got V"
BOUNDS = (POSITIVE, NON_NEGATIVE, FINITE, FINITE_POSITIVE)
# The largest --aug_pos_sigma (m) and --aug_yaw_sigma (rad): a kept start lies 0.08..0.26 m from the target
# (datagen.tasks.pusht.R_LO, R_HI), so a 10 m std almost never lands one, and a yaw wraps every 6.3 rad;
# beyond that a value can only waste attempts, and 1e308 overflows the angle to inf (math domain error).
SIGMA_MAX = 10.0
# datagen.task.modes_of (not imported here: --help stays instant)
MODES = ("resolve", "replay", "replay_live")


def flag(default, help: str, *, bound=None, at_most=None, aliases=(), why=None, **argparse_kw):
    """A dataclass field that is one command-line flag --NAME (NAME: the field's name).

    default: its value when not given (a list for nargs="+"; True/False make a switch: True an on/off
    pair --NAME/--no-NAME, False a plain --NAME, or on/off with action=argparse.BooleanOptionalAction);
    help: one line, with its unit and why its default; bound: one of BOUNDS, checked value by value;
    at_most: its largest value; why: with both a bound and at_most, the error names the whole range and
    why ("--NAME must be in [1, 1000000] (WHY), got V"); aliases: older spellings (--NAME2) that still
    work, the same flag; argparse_kw: what else argparse needs (type, choices, nargs, metavar, const,
    required, action)."""
    meta = dict(help=help, bound=bound, at_most=at_most, why=why, aliases=tuple(aliases), kw=argparse_kw)
    if bound not in (None, *BOUNDS):
        raise ValueError(f"unknown bound {bound!r}")
    if isinstance(default, list):
        return dataclasses.field(default_factory=lambda: list(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def fields(cls) -> list[dataclasses.Field]:
    """cls's flags: every dataclass field made by flag()."""
    return [f for f in dataclasses.fields(cls) if "help" in f.metadata]


def _default(f: dataclasses.Field):
    return f.default_factory() if f.default is dataclasses.MISSING else f.default


def _group_of(cls, f: dataclasses.Field) -> type:
    """The class in cls's MRO that declares f: its argument group in --help."""
    return next(c for c in reversed(cls.__mro__) if f.name in getattr(c, "__annotations__", {}))


def parser_of(
    cls, prog: str | None = None, description: str | None = None, helps: dict | None = None
) -> argparse.ArgumentParser:
    """The parser of command dataclass `cls`: its own flags first, then one argument group per class it
    takes flags from (in its bases' order, the class docstring's first line the group's title), every
    flag's default in --help. `helps` {name: help} replace fields' help known only at run time (a
    task's units)."""
    p = parser(description or (cls.__doc__ or "").strip(), prog=prog)
    by_owner = {}
    for f in fields(cls):
        by_owner.setdefault(_group_of(cls, f), []).append(f)
    for owner in (c for c in cls.__mro__ if c in by_owner):
        group = p if owner is cls else p.add_argument_group((owner.__doc__ or owner.__name__).strip())
        for f in by_owner[owner]:
            m, default = f.metadata, _default(f)
            kw = dict(m["kw"], default=default, help=(helps or {}).get(f.name, m["help"]))
            if isinstance(default, bool) and "action" not in kw:
                kw["action"] = argparse.BooleanOptionalAction if default else "store_true"
            elif "type" not in kw and "action" not in kw and default is not None:
                kw["type"] = type(default[0]) if isinstance(default, list) else type(default)
            if kw.get("type") is Path:
                kw["type"] = _path
            if m["aliases"] and "action" not in kw:  # each spelling's value kept: parse() refuses two
                kw["action"] = _Spellings
            group.add_argument(f"--{f.name}", *(f"--{a}" for a in m["aliases"]), dest=f.name, **kw)
    return p


class _Spellings(argparse._StoreAction):
    """A flag with old spellings (flag(aliases=...)): stores its value and keeps each spelling's, so that
    parse() refuses `--per_demo 2 --attempts_per_demo 3` instead of letting the last one win silently."""

    def __call__(self, parser, namespace, values, option_string=None):
        self.given = {**getattr(self, "given", {}), option_string: values}
        super().__call__(parser, namespace, values, option_string)


def disagreement(p: argparse.ArgumentParser) -> str | None:
    """One line naming the two spellings of one flag given with different values, else None."""
    for action in p._actions:
        given = list(getattr(action, "given", {}).items())
        for (s1, v1), (s2, v2) in zip(given, given[1:]):
            if v1 != v2:
                shown = [" ".join(map(str, v)) if isinstance(v, list) else v for v in (v1, v2)]
                said = f"{s1} {shown[0]} and {s2} {shown[1]}"
                return f"{said} are one flag (an old and a new spelling) given two values; give it once"
    return None


def spelled(argv, cls) -> dict[str, str]:
    """{field name: the spelling the command line used for it}, for the flags given under an alias:
    an error names the flag as it was typed (`--pos_sigma must be at most 10` for --pos_sigma 11)."""
    said = {}
    for f in fields(cls):
        for a in f.metadata["aliases"]:
            if any(t == f"--{a}" or t.startswith(f"--{a}=") for t in argv):
                said[f.name] = a
    return said


def check_fields(args, cls, argv=None) -> None:
    """DataError (one line) for the first flag of `args` out of the bound its field in `cls` declares."""
    said = spelled(sys.argv[1:] if argv is None else [str(t) for t in argv], cls)
    for f in fields(cls):  # a range with its why: one message for either end
        lo, hi, why = (
            {POSITIVE: 1, NON_NEGATIVE: 0}.get(f.metadata["bound"]),
            f.metadata["at_most"],
            f.metadata["why"],
        )
        for v in _values(args, f.name) if why else []:
            if not lo <= v <= hi:
                raise DataError(f"--{said.get(f.name, f.name)} must be in [{lo}, {hi}] ({why}), got {v}")
    by = {b: [f.name for f in fields(cls) if f.metadata["bound"] == b] for b in BOUNDS}
    most = {f.name: f.metadata["at_most"] for f in fields(cls) if f.metadata["at_most"] is not None}
    check(args, by[POSITIVE], by[NON_NEGATIVE], by[FINITE], by[FINITE_POSITIVE], most, said)


def parse(
    cls,
    argv=None,
    *,
    prog=None,
    description=None,
    smoke: dict | None = None,
    defaults: dict | None = None,
    helps: dict | None = None,
) -> argparse.Namespace:
    """Parse and check the flags of command dataclass `cls`; a problem is a DataError (one line, exit 2).
    `defaults` replace fields' defaults and `helps` their help, known only at run time (the task's noise
    and its unit); with `smoke` and --smoke given, smoke's values are the defaults (flags given
    explicitly win)."""
    p = parser_of(cls, prog, description, helps)
    p.set_defaults(**(defaults or {}))
    args = p.parse_args(argv)
    if smoke and getattr(args, "smoke", False):
        p.set_defaults(**smoke)
        args = p.parse_args(argv)
    if problem := disagreement(p):
        raise DataError(problem)
    check_fields(args, cls, argv)
    return args


def _path(text: str) -> Path:
    if not text.strip():
        raise argparse.ArgumentTypeError("a path must not be empty")
    return Path(text)


def parser(description: str, prog: str | None = None) -> argparse.ArgumentParser:
    """An ArgumentParser whose errors are DataErrors (one line, exit 2) and whose Path flags refuse
    an empty string (which would silently mean the current folder)."""

    class Parser(argparse.ArgumentParser):
        def error(self, message):
            raise DataError(f"{message} (see --help)")

        def add_argument(self, *names, **kw):
            if kw.get("type") is Path:
                kw["type"] = _path
            return super().add_argument(*names, **kw)

    return Parser(prog=prog, description=description, formatter_class=_Help, allow_abbrev=False)


class _Help(argparse.RawDescriptionHelpFormatter):
    """--help shows every flag's default after its help (on/off for a switch), unless the help already
    names it ("default ...": one that is computed, such as --out's)."""

    def _get_help_string(self, action):
        text, default = action.help or "", action.default
        said = re.search(r"\bdefault\b", text)  # "default 12", "(default: cores)": said in words
        if not action.option_strings or default is None or default is argparse.SUPPRESS or said:
            return text
        shown = ("off", "on")[default] if isinstance(default, bool) else "%(default)s"
        return f"{text} (default: {shown})"


def _values(args, name) -> list:
    """The flag's values: a flag of several (nargs="+") is checked value by value; None (not given, a
    default computed later, such as --workers') is not checked."""
    v = getattr(args, name)
    return list(v) if isinstance(v, (list, tuple)) else [] if v is None else [v]


def check(args, positive=(), non_negative=(), finite=(), finite_positive=(), at_most=None, said=None) -> None:
    """DataError (one line) for the first flag of `args` out of its range: `positive` and
    `non_negative` integers, `finite` non-negative and `finite_positive` positive numbers, and {flag: its
    maximum}; `said` {name: spelling} names a flag given under an old spelling as it was typed.
    A flag that takes several values (nargs="+") is checked value by value."""
    said = said or {}
    for name in positive:
        for v in _values(args, name):
            if v <= 0:
                raise DataError(f"--{said.get(name, name)} must be a positive integer, got {v}")
    for name in non_negative:
        for v in _values(args, name):
            if v < 0:
                raise DataError(f"--{said.get(name, name)} must be >= 0, got {v}")
    for kind, names in (("non-negative", finite), ("positive", finite_positive)):
        for name in names:
            for v in _values(args, name):
                # -0.0 passes `v < 0` but numpy's samplers refuse it as a negative scale: its sign bit counts
                if not math.isfinite(v) or math.copysign(1.0, v) < 0 or (kind == "positive" and v == 0):
                    raise DataError(f"--{said.get(name, name)} must be a finite {kind} number, got {v}")
    for name, most in (at_most or {}).items():
        for v in _values(args, name):
            if v > most:
                raise DataError(f"--{said.get(name, name)} must be at most {most}, got {v}")


# --- the groups several commands share ----------------------------------------------------------
@dataclass(frozen=True)
class Recipe:
    """the BC training recipe (bc_recipe.py), the lesson's and the Scale Lab's"""

    epochs: int = flag(
        500,
        "passes over a data set that make a training budget (scale_data.py: see measure; scale_lab.py: "
        "over the resolve set at N)",
        bound=POSITIVE,
    )
    batch_size: int = flag(128, "frames per gradient step", bound=POSITIVE)
    lr: float = flag(1e-3, "Adam learning rate, cosine-decayed to 0", bound=FINITE_POSITIVE, at_most=1.0)
    hidden_dim: int = flag(512, "width of both hidden layers of the BC MLP", bound=POSITIVE)


@dataclass(frozen=True)
class Perturbation:
    """the data engine's perturbation of a source start (datagen.Perturbation)"""

    aug_pos_sigma: float = flag(
        0.08,
        "m; std of the position moves a task's perturb draws for a start (PushT: block and pusher xy; "
        "ALOHA: cube, target and both arms; the 3-D tasks: their objects' xy; gym-pusht: at 1 px a mm) "
        f"(<= {SIGMA_MAX:g})",
        bound=FINITE,
        at_most=SIGMA_MAX,
        aliases=("pos_sigma",),
    )
    aug_yaw_sigma: float = flag(
        0.5,
        "rad; std of the yaw moves of a start's objects (PushT's and gym-pusht's block; a task whose "
        f"objects do not turn ignores it) (<= {SIGMA_MAX:g})",
        bound=FINITE,
        at_most=SIGMA_MAX,
        aliases=("yaw_sigma",),
    )


@dataclass(frozen=True)
class Mode:
    """how the data engine makes a demo from a perturbed start"""

    aug_mode: str = flag(
        "resolve",
        "resolve: the expert solves each perturbed start; replay: MimicGen's move, the source path "
        "transformed into the new object poses and executed open-loop (no solver), kept only on success "
        "(on PushT most attempts fail here; ALOHA replays subtask by subtask); replay_live: the same replay "
        "following the object's live pose: once an object frame lies farther from where the replayed segment "
        "expects it than the task's follow tolerance (PushT 2 mm and 0.02 rad, gym-pusht 2 px and 0.02 rad: "
        "more than contact jitter), the rest of the segment is re-expressed from its pose now (no solver)",
        choices=MODES,
        aliases=("mode",),
    )


@dataclass(frozen=True)
class Parallel:
    """how many processes (the same results for any number)"""

    workers: int = flag(
        None,
        "worker processes; same results for any number (default: cores, at most 8)",
        bound=POSITIVE,
        type=int,
    )


@dataclass(frozen=True)
class Ray(Parallel):
    """on Ray instead of local processes (the same results); with --ray, --workers is a local Ray's CPUs"""

    ray: str = flag(
        None,
        "run on Ray: alone, a private local Ray with --workers CPUs; with ADDRESS, join that cluster",
        nargs="?",
        const="local",
        metavar="ADDRESS",
    )


@dataclass(frozen=True)
class Tries:
    """how long the data engine tries"""

    aug_tries: int = flag(
        100,
        "attempts per wanted demo before a source demo gives up (replay's success filter rejects most)",
        bound=POSITIVE,
    )


@dataclass(frozen=True)
class Chapter(Tries, Perturbation, Recipe):
    """The chapter's experiment as the tools and the exercises read it (CHAPTER). scale_data.py declares
    these flags itself, each with its unit and why (the lesson's knobs are read where they are used);
    tests/test_flags.py keeps its defaults and these equal."""

    source_episodes: int = 12
    aug_per_demo: int = 8
    eval_episodes: int = 50
    seed: int = 0


CHAPTER = Chapter()
DEFAULTS = asdict(CHAPTER)
SMOKE = dict(
    source_episodes=4, aug_per_demo=2, epochs=30, hidden_dim=64, eval_episodes=8, batch_size=64, device="cpu"
)
RESULT_FILES = tuple(
    "metrics.json cross_embodiment.json scale_data.png scale_data.html scale_data.rrd".split()
)
NOT_IN_KEY = ("out", "cache", "workers")  # where results go and how fast they come never change them


def default_workers() -> int:
    """--workers when not given: the cores, at most 8 (a --workers flag's default None means this)."""
    import os

    return min(8, os.cpu_count() or 1)
