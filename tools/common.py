"""What every tool shares: the paths it works on, its flag parser and subcommands, its --out check, the
regions of scale_data.py (parsed and hashed), and the provenance a result records.

Region hash: sha256 (hex) of the region's body, that is the lines strictly between its
`# --- region: NAME ---` and `# --- endregion ---` markers, each line ending in "\\n", UTF-8.
Markers are excluded (the name is the key; the parser enforces the order).
"""

from __future__ import annotations

import argparse
import ast
import datetime
import hashlib
import importlib.metadata
import inspect
import json
import math
import os
import platform
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from ch37 import ROOT, cli, config
from ch37.errors import DataError
from ch37.ownership import check_out_path, check_own_result, dump_json, round_floats, write_atomic
from ch37.process import has_avx2_fma

SCRIPT = ROOT / "scale_data.py"
META = ROOT / "meta.yaml"
WALLCLOCK = ROOT / "wallclock.csv"
NOTEBOOK = ROOT / "scale_data.ipynb"


def parser(name: str, doc: str, script: bool = True) -> argparse.ArgumentParser:
    """ch37.config.parser for `python -m tools.NAME` (NAME: a tool, or a tool and its subcommand), with the
    --script a tool reads the chapter from (`script`); `doc` (a function's docstring too) unindented."""
    p = config.parser(inspect.cleandoc(doc), prog=f"python -m tools.{name}")
    if script:
        p.add_argument("--script", type=Path, default=SCRIPT, help="chapter script (default scale_data.py)")
    return p


def subcommands(tool: str, commands: dict, argv: list[str], doc: str) -> int:
    """`python -m tools.TOOL SUBCOMMAND [FLAGS]`: commands[SUBCOMMAND](FLAGS), each subcommand parsing its
    own flags (`SUBCOMMAND --help`); --help alone prints `doc`, the tool's list of them."""
    if argv[:1] in (["-h"], ["--help"]):
        print(doc.strip())
        return 0
    if not argv or argv[0] not in commands:
        got = f"unknown subcommand {argv[0]!r}" if argv else "a subcommand is missing"
        raise DataError(f"{got}: python -m tools.{tool} takes one of {', '.join(commands)} (see --help)")
    return commands[argv[0]](argv[1:])


def check_results(out: Path, *kinds: str, beside: dict | None = None) -> None:
    """A tool's --out, before any work: refused (one line) if it cannot hold results, or if OUT/KIND.json
    for one of `kinds` is not this tool's (an earlier run's may be replaced, a user's file never);
    beside {kind: files written after that result, a figure} (ch37.ownership.check_own_result)."""
    if problem := check_out_path(out):
        raise DataError(problem)
    for kind in kinds:
        check_own_result(out / f"{kind}.json", kind, beside=(beside or {}).get(kind, ()))


def _t_cdf(t: float, dof: int) -> float:
    """Student's t CDF at t > 0: 1 - I_x(dof/2, 1/2) / 2 with x = dof / (dof + t^2), the regularized
    incomplete beta by its continued fraction (Lentz), as no scipy is in the lock."""
    a, b, x = dof / 2, 0.5, dof / (dof + t * t)
    front = math.exp(
        math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x)
    )
    c, d = 1.0, 1.0 - (a + b) * x / (a + 1)
    d = 1 / d
    f = d
    for m in range(1, 300):
        for num in (
            m * (b - m) * x / ((a + 2 * m - 1) * (a + 2 * m)),
            -(a + m) * (a + b + m) * x / ((a + 2 * m) * (a + 2 * m + 1)),
        ):
            d = 1 / (1 + num * d)
            c = 1 + num / c
            f *= c * d
    return 1 - front * f / a / 2


def t975(dof: int) -> float:
    """The t distribution's 97.5% quantile for `dof` degrees of freedom, to 3 decimals (the printed
    tables' 12.706, 4.303, ..., 2.228 for 1..10; 2.010 at 49, 1.976 at 149): the "95% t" of every
    interval mean_ci gives, at any dof (a normal 1.96 above 10 dof made a t-labelled interval narrower)."""
    lo, hi = 1.9, 13.0
    for _ in range(60):  # bisection: the CDF is increasing in t
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if _t_cdf(mid, dof) < 0.975 else (lo, mid)
    return round((lo + hi) / 2, 3)


def mean_ci(d: list[float]) -> tuple[float, float | None, list[float] | None]:
    """Mean, sample std and 95% t-interval of the mean of `d` (std and interval None with one value)."""
    n = len(d)
    mean = sum(d) / n
    std = math.sqrt(sum((x - mean) ** 2 for x in d) / (n - 1)) if n > 1 else None
    half = None if std is None else t975(n - 1) * std / math.sqrt(n)
    return mean, std, None if half is None else [mean - half, mean + half]


def in_fresh_process(code: str, args: list, env: dict | None = None, what: str = "the process") -> dict:
    """Run `code` in a new Python (its arguments `args`, environment `env`); the JSON of its last line."""
    p = subprocess.run(
        [sys.executable, "-c", code, *map(str, args)], cwd=ROOT, env=env, capture_output=True, text=True
    )
    if p.returncode != 0:
        raise DataError(f"{what} failed: {(p.stderr.strip().splitlines() or [''])[-1]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def write_result(path: Path, result: dict) -> Path:
    """A tool's JSON result, floats to 4 digits (ch37.ownership.round_floats), written whole or not at all."""
    return write_atomic(path, dump_json(round_floats(result)))


def rel(p: Path) -> str:
    """`p` relative to the repository root when it lies inside it, else as given (absolute)."""
    p = Path(p).resolve()
    return str(p.relative_to(ROOT)) if p.is_relative_to(ROOT) else str(p)


def supports_flag(script: Path, flag: str) -> bool:
    """Whether the chapter script defines `flag` (read from its source, so nothing is run): as a field of
    its Args dataclass (`cache: bool = flag(...)`, ch37.config.flag), or, in a script from before those,
    as an argparse string ("--cache")."""
    text = Path(script).read_text(encoding="utf-8")
    field = re.compile(rf"^\s+{re.escape(flag.removeprefix('--'))}\s*:[^=\n]*=\s*flag\(", re.MULTILINE)
    return f'"{flag}"' in text or field.search(text) is not None


REGION_ORDER = ("setup", "wrangle", "augment", "measure", "emit")
OPEN_RE = re.compile(r"# --- region: (\S+) ---")
CLOSE = "# --- endregion ---"
# anything that tries to be a marker
MARKERISH = re.compile(r"^\s*#\s*-{2,}\s*(end\s*)?region\b", re.IGNORECASE)


class RegionError(DataError):
    """The script's region markers are malformed (or the script cannot be read)."""


@dataclass(frozen=True)
class Region:
    name: str
    start: int  # 1-based line of the opening marker
    end: int  # 1-based line of the endregion marker
    body: str  # lines strictly between the markers, each ending in "\n"

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.body.encode("utf-8")).hexdigest()

    @property
    def intent(self) -> list[str]:
        """The comment block that opens the region (its statement of intent), without '# '."""
        lines = self.body.splitlines()
        n = next((i for i, line in enumerate(lines) if not line.startswith("#")), len(lines))
        return [line[1:].strip() for line in lines[:n]]

    @property
    def code(self) -> str:
        """The body after the intent comment, blank lines at both ends removed."""
        return "\n".join(self.body.splitlines()[len(self.intent) :]).strip("\n")


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RegionError(f"{rel(path)}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise RegionError(f"{rel(path)}: cannot be read ({e})") from None


def parse_regions(path: Path = SCRIPT) -> list[Region]:
    """The five regions of the chapter script, in order; RegionError on any malformed marker layout."""
    path = Path(path)
    text, order = _read(path), ", ".join(REGION_ORDER)

    def bad(n, msg) -> RegionError:  # names the file and the line
        return RegionError(f"{path.name}{f':{n}' if n else ''}: {msg}")

    try:
        tree = ast.parse(text)
    except SyntaxError as e:
        raise bad(e.lineno, f"not valid Python ({e.msg})") from None
    doc = tree.body[0] if tree.body and ast.get_docstring(tree) is not None else None
    doc_lines = range(doc.lineno, doc.end_lineno + 1) if doc else range(0)
    regions: list[Region] = []
    open_name, open_line, body = None, 0, []
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.rstrip()
        if m := OPEN_RE.fullmatch(line):
            name = m.group(1)
            if open_name is not None:
                raise bad(
                    n,
                    f"region {name!r} opens inside region {open_name!r} (opened at line {open_line}); "
                    f"regions do not nest, close it with '{CLOSE}' first",
                )
            if name not in REGION_ORDER:
                raise bad(n, f"unknown region name {name!r}; the regions are {order}")
            if name in [r.name for r in regions]:
                raise bad(n, f"duplicate region {name!r}")
            if name != (expected := REGION_ORDER[len(regions)]):
                raise bad(n, f"region {name!r} is out of order: expected {expected!r} here (order: {order})")
            open_name, open_line, body = name, n, []
        elif line == CLOSE:
            if open_name is None:
                raise bad(n, f"'{CLOSE}' without an open region")
            regions.append(Region(open_name, open_line, n, "".join(b + "\n" for b in body)))
            open_name = None
        elif MARKERISH.match(raw):
            raise bad(
                n,
                f"malformed region marker {raw.strip()!r}; markers are exactly "
                f"'# --- region: NAME ---' and '{CLOSE}' at column 0",
            )
        elif open_name is not None:
            body.append(raw)
        elif line.strip() and n not in doc_lines and not (n == 1 and line.startswith("#!")):
            raise bad(
                n,
                f"code outside any region: {line.strip()[:60]!r} "
                "(only the module docstring may live outside the regions)",
            )
    if open_name is not None:
        raise bad(open_line, f"region {open_name!r} has no '{CLOSE}'")
    if missing := REGION_ORDER[len(regions) :]:
        raise bad(None, f"missing region(s) {', '.join(missing)}; the regions are {order}")
    return regions


def region_hashes(path: Path = SCRIPT) -> dict[str, str]:
    return {r.name: r.sha256 for r in parse_regions(path)}


def drifted(current: dict[str, str], recorded: dict | None) -> list[str]:
    """Region names whose hash differs from (or is missing in) meta.yaml's region_hashes."""
    recorded = recorded or {}
    return [k for k in dict.fromkeys([*current, *recorded]) if current.get(k) != recorded.get(k)]


def module_docstring(path: Path = SCRIPT) -> str:
    return ast.get_docstring(ast.parse(_read(Path(path)))) or ""


def _run(*cmd: str) -> subprocess.CompletedProcess | None:
    try:
        return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    except OSError:  # no such program here
        return None


def _cpu_model() -> str:
    info = Path("/proc/cpuinfo")  # Linux
    lines = info.read_text().splitlines() if info.exists() else []
    models = [ln.split(":", 1)[1].strip() for ln in lines if ln.startswith("model name")]
    cpu = models[0] if models else platform.processor()
    if not cpu and sys.platform == "darwin":
        mac = _run("sysctl", "-n", "machdep.cpu.brand_string")
        cpu = mac.stdout.strip() if mac else ""
    return cpu or ""


def _git() -> dict | None:
    head = _run("git", "rev-parse", "HEAD")
    dirty = _run("git", "status", "--porcelain", "--untracked-files=no")
    if head is None or head.returncode != 0:
        return None
    return {"commit": head.stdout.strip(), "dirty": bool(dirty.stdout.strip())}


def _version(pkg: str) -> str | None:
    try:
        return importlib.metadata.version(pkg)
    except importlib.metadata.PackageNotFoundError:
        return None


def _kernel_path(script: Path) -> str:
    """The kernel path (OPENBLAS_CORETYPE, MKL_CBWR) the runs of `script` take: what is set here is
    theirs, else scale_data.py's setup region holds its runs to ch37.cli's published path
    (docs/reproducibility.md)."""
    lesson = Path(script).name == "scale_data.py"
    core = os.environ.get("OPENBLAS_CORETYPE") or (
        cli.PUBLISHED_BLAS_CORE if lesson and has_avx2_fma() else ""
    )
    mkl = os.environ.get("MKL_CBWR") or (cli.PUBLISHED_MKL_CBWR if lesson else "")
    held = " (scale_data.py's setup region)" if lesson else ""
    return f"OpenBLAS {core or 'own choice'}, MKL {mkl or 'own branch'}{held}"


def provenance(script: Path) -> dict:
    """Where and with what a run happened: date, git commit, platform, package versions, region hashes."""
    try:
        hashes = region_hashes(script)
    except RegionError:
        hashes = None
    return {
        "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "git": _git(),
        "platform": {
            "python": platform.python_version(),
            "os": platform.platform(),
            "machine": platform.machine(),
            "cpu_count": os.cpu_count(),
            "cpu_model": _cpu_model(),
            "kernel_path": _kernel_path(script),
        },
        "packages": {p: _version(p) for p in ("torch", "lerobot", "mujoco", "numpy")},
        "script_region_hashes": hashes,
    }
