"""The chapter's defaults in one place, and the one flag checker every command uses.

CHAPTER holds the lesson's default configuration (scale_data.py's flags take their defaults from it,
and so do augment_demos.py, scale_lab.py and the tools where they mean the same thing); SMOKE the
tiny CPU configuration of --smoke. parser() and check() make every command's flag problems one
`error:` line and exit 2 (through ch37.errors), before any heavy import.
"""

from __future__ import annotations

import argparse
import math
import re
from dataclasses import asdict, dataclass
from pathlib import Path

from ch37.errors import DataError


@dataclass(frozen=True)
class Chapter:
    source_episodes: int = 12  # expert demos per robot: coverage-starved on purpose
    aug_per_demo: int = 8  # generated demos kept per PushT source demo
    aug_pos_sigma: float = 0.08  # m, block and pusher xy perturbation
    aug_yaw_sigma: float = 0.5  # rad, block yaw perturbation
    aug_tries: int = 100  # attempts per wanted demo before a source demo gives up
    epochs: int = 500  # passes over a data set that make a training budget
    batch_size: int = 128  # frames per gradient step
    lr: float = 1e-3  # Adam, cosine-decayed to 0
    hidden_dim: int = 512  # width of both hidden layers of the BC MLP
    eval_episodes: int = 50  # held-out PushT starts per arm
    seed: int = 0


CHAPTER = Chapter()
DEFAULTS = asdict(CHAPTER)
SMOKE = dict(
    source_episodes=4, aug_per_demo=2, epochs=30, hidden_dim=64, eval_episodes=8, batch_size=64, device="cpu"
)
RESULT_FILES = tuple(
    "metrics.json cross_embodiment.json scale_data.png scale_data.html scale_data.rrd".split()
)
# The largest --*pos_sigma (m) and --*yaw_sigma (rad): a kept start lies 0.08..0.26 m from the target
# (datagen.pusht.R_LO, R_HI), so a 10 m std almost never lands one, and a yaw wraps every 6.3 rad;
# beyond that a value can only waste attempts, and 1e308 overflows the angle to inf (math domain error).
SIGMA_MAX = 10.0
NOT_IN_KEY = ("out", "cache", "workers")  # where results go and how fast they come never change them


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
    """The flag's values: a flag of several (nargs="+") is checked value by value."""
    v = getattr(args, name)
    return list(v) if isinstance(v, (list, tuple)) else [v]


def check(args, *, positive=(), non_negative=(), finite=(), at_most=None) -> None:
    """DataError (one line) for the first flag of `args` out of its range: `positive` and
    `non_negative` integers, `finite` non-negative numbers (lr: positive), and {flag: its maximum}.
    A flag that takes several values (nargs="+") is checked value by value."""
    for name in positive:
        for v in _values(args, name):
            if v <= 0:
                raise DataError(f"--{name} must be a positive integer, got {v}")
    for name in non_negative:
        for v in _values(args, name):
            if v < 0:
                raise DataError(f"--{name} must be >= 0, got {v}")
    for name in finite:
        for v in _values(args, name):
            if not math.isfinite(v) or v < 0 or (name == "lr" and v == 0):
                kind = "positive" if name == "lr" else "non-negative"
                raise DataError(f"--{name} must be a finite {kind} number, got {v}")
    for name, most in (at_most or {}).items():
        for v in _values(args, name):
            if v > most:
                raise DataError(f"--{name} must be at most {most}, got {v}")
