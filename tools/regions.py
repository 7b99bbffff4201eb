"""The five regions of scale_data.py: parse them, hash them, compare with meta.yaml.

    python -m tools.regions            each region: name, line range, sha256
    python -m tools.regions --check    exit 1 naming every region that drifted from meta.yaml
    python -m tools.regions --write    refresh meta.yaml's region_hashes (nothing else)

Region hash: sha256 (hex) of the region's body, that is the lines strictly between its
`# --- region: NAME ---` and `# --- endregion ---` markers, each line ending in "\\n", UTF-8.
Markers are excluded (the name is the key; the parser enforces the order).

Exit codes: 0 ok, 1 drift, 2 bad input (a missing file, malformed markers, bad flags).
"""

from __future__ import annotations

import ast
import hashlib
import re
from dataclasses import dataclass
from pathlib import Path

from tools.common import META, SCRIPT, ToolError, _rel, parser, run_cli

REGION_ORDER = ("setup", "wrangle", "augment", "measure", "emit")
OPEN_RE = re.compile(r"# --- region: (\S+) ---")
CLOSE = "# --- endregion ---"
MARKERISH = re.compile(
    r"^\s*#\s*-{2,}\s*(end\s*)?region\b", re.IGNORECASE
)  # anything that tries to be a marker


class RegionError(ToolError):
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
        out = []
        for line in self.body.splitlines():
            if not line.startswith("#"):
                break
            out.append(line[1:].strip())
        return out

    @property
    def code(self) -> str:
        """The body after the intent comment, blank lines at both ends removed."""
        lines = self.body.splitlines()
        return "\n".join(lines[len(self.intent) :]).strip("\n")


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RegionError(f"{_rel(path)}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise RegionError(f"{_rel(path)}: cannot be read ({e})") from None


def _docstring_lines(tree: ast.Module) -> set[int]:
    first = tree.body[0] if tree.body else None
    if (
        isinstance(first, ast.Expr)
        and isinstance(first.value, ast.Constant)
        and isinstance(first.value.value, str)
    ):
        return set(range(first.lineno, first.end_lineno + 1))
    return set()


def parse_regions(path: Path = SCRIPT, text: str | None = None) -> list[Region]:
    """The five regions of the chapter script, in order; RegionError on any malformed marker layout."""
    path = Path(path)
    text = _read(path) if text is None else text
    where = path.name
    try:
        tree = ast.parse(text)
    except SyntaxError as e:
        raise RegionError(f"{where}:{e.lineno}: not valid Python ({e.msg})") from None
    doc_lines = _docstring_lines(tree)
    order = ", ".join(REGION_ORDER)
    regions: list[Region] = []
    seen: set[str] = set()
    open_name, open_line, body = None, 0, []
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.rstrip()
        m = OPEN_RE.fullmatch(line)
        if m:
            name = m.group(1)
            if open_name is not None:
                raise RegionError(
                    f"{where}:{n}: region {name!r} opens inside region {open_name!r} (opened at line "
                    f"{open_line}); regions do not nest, close it with '{CLOSE}' first"
                )
            if name not in REGION_ORDER:
                raise RegionError(f"{where}:{n}: unknown region name {name!r}; the regions are {order}")
            if name in seen:
                raise RegionError(f"{where}:{n}: duplicate region {name!r}")
            expected = REGION_ORDER[len(regions)]
            if name != expected:
                raise RegionError(
                    f"{where}:{n}: region {name!r} is out of order: expected {expected!r} here "
                    f"(order: {order})"
                )
            seen.add(name)
            open_name, open_line, body = name, n, []
        elif line == CLOSE:
            if open_name is None:
                raise RegionError(f"{where}:{n}: '{CLOSE}' without an open region")
            regions.append(Region(open_name, open_line, n, "".join(b + "\n" for b in body)))
            open_name = None
        elif MARKERISH.match(raw):
            raise RegionError(
                f"{where}:{n}: malformed region marker {raw.strip()!r}; markers are exactly "
                f"'# --- region: NAME ---' and '{CLOSE}' at column 0"
            )
        elif open_name is not None:
            body.append(raw)
        elif line.strip() and n not in doc_lines and not (n == 1 and line.startswith("#!")):
            raise RegionError(
                f"{where}:{n}: code outside any region: {line.strip()[:60]!r} "
                "(only the module docstring may live outside the regions)"
            )
    if open_name is not None:
        raise RegionError(f"{where}:{open_line}: region {open_name!r} has no '{CLOSE}'")
    missing = [r for r in REGION_ORDER if r not in seen]
    if missing:
        raise RegionError(f"{where}: missing region(s) {', '.join(missing)}; the regions are {order}")
    return regions


def region_hashes(path: Path = SCRIPT) -> dict[str, str]:
    return {r.name: r.sha256 for r in parse_regions(path)}


def drifted(current: dict[str, str], recorded: dict | None) -> list[str]:
    """Region names whose hash differs from (or is missing in) meta.yaml's region_hashes."""
    recorded = recorded or {}
    names = list(current) + [k for k in recorded if k not in current]
    return [k for k in names if current.get(k) != recorded.get(k)]


def module_docstring(path: Path = SCRIPT) -> str:
    path = Path(path)
    return ast.get_docstring(ast.parse(_read(path))) or ""


def main(argv: list[str] | None = None) -> int:
    p = parser("regions", __doc__)
    g = p.add_mutually_exclusive_group()
    g.add_argument(
        "--check", action="store_true", help="exit 1 naming each region that drifted from meta.yaml"
    )
    g.add_argument("--write", action="store_true", help="rewrite region_hashes in meta.yaml (nothing else)")
    p.add_argument("--meta", type=Path, default=META, help="default meta.yaml")
    a = p.parse_args(argv)
    if not (a.check or a.write):
        for r in parse_regions(a.script):
            print(f"{r.name:8s} lines {r.start:4d}-{r.end:<4d} sha256 {r.sha256}")
        print("(sha256 of the lines strictly between the markers, each ending in a newline)")
        return 0
    from tools.meta import META_STATIC, load_yaml, write_meta

    current = region_hashes(a.script)
    meta = load_yaml(a.meta)
    if a.write:
        meta["region_hashes"] = current
        write_meta(a.meta, meta if meta.get("id") else {**META_STATIC, **meta})
        print(f"wrote region_hashes of {_rel(a.script)} to {_rel(a.meta)}")
        return 0
    if not meta.get("region_hashes"):
        print(f"drift: {_rel(a.meta)} has no region_hashes; run: python -m tools.regions --write")
        return 1
    bad = drifted(current, meta["region_hashes"])
    if bad:
        print(
            f"drift: region(s) {', '.join(bad)} of {_rel(a.script)} differ from {_rel(a.meta)} "
            "region_hashes; if the change is intended, run: python -m tools.regions --write "
            "(and re-run the sweeps + python -m tools.meta if the numbers may have moved)"
        )
        return 1
    print(f"ok: all {len(current)} regions match {_rel(a.meta)}")
    return 0


if __name__ == "__main__":
    run_cli(main)
