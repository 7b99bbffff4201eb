"""scale_data.ipynb from the regions of scale_data.py: one markdown and one code cell per region.

    python -m tools.notebook            write scale_data.ipynb
    python -m tools.notebook --check    exit 1 if scale_data.ipynb does not match the script

The notebook is deterministic (fixed cell ids, no timestamps, no outputs), so --check is a byte
comparison. Edit the script, not the notebook.

Exit codes: 0 ok, 1 stale notebook, 2 bad input (malformed markers, bad flags).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from ch37 import errors
from ch37.ownership import write_atomic
from tools.common import NOTEBOOK, SCRIPT, module_docstring, parse_regions, parser, rel, supports_flag

INSTALL_CELL = """\
# Install (idempotent). Open this notebook from a clone of the course repository, or on Colab first
# upload/clone the repository into the working folder. This cell finds it (here or one folder down),
# moves into it, and installs the project only when lerobot is not importable yet.
# If pip upgraded numpy or torch, Colab asks to restart the runtime: restart, then run from here again.
import importlib.util
import os
import sys
from pathlib import Path

here = Path.cwd()
candidates = [here, *sorted(p.parent for p in here.glob("*/scale_data.py"))]
repo = next((d for d in candidates if (d / "scale_data.py").is_file()), None)
if repo is None:
    raise FileNotFoundError(f"scale_data.py is not in {here} or a folder below it: get the course repository")
os.chdir(repo)
if str(repo) not in sys.path:
    sys.path.insert(0, str(repo))
if importlib.util.find_spec("lerobot") is None:
    %pip install -q -e .
print(f"repository {repo}; lerobot {'ready' if importlib.util.find_spec('lerobot') else 'missing'}")"""

ARGV_CELL = """\
# The script's flags, exactly as on the command line (python scale_data.py --help lists them).
# Smoke run, seconds, numbers not meaningful:  sys.argv = ["scale_data.py", "--smoke", "--seed", "0"]
{cache_note}import sys

sys.argv = ["scale_data.py", "--seed", "0", "--no-cache"]"""
POSTER_CELL = """\
# The poster this run wrote beside its PNG: scale_data.html, one self-contained page (inline SVG and
# CSS, no script, nothing fetched), shown here inline. The file opens in any browser, shared as is.
from IPython.display import HTML

HTML((args.out / "scale_data.html").read_text(encoding="utf-8"))"""
CACHE_NOTE = """\
# --no-cache: every cell really runs. Without it an identical earlier run (same flags, same code)
# is replayed from the result cache and the setup cell stops the notebook early ("SystemExit: 0").
"""


def _prose(text: str) -> str:
    """Docstring paragraphs -> markdown: plain ones joined, aligned/indented ones kept as text blocks."""
    out = []
    for para in re.split(r"\n\s*\n", text.strip()):
        lines = para.splitlines()
        if any(ln.startswith((" ", "\t")) or re.search(r"\S {2,}\S", ln) for ln in lines):
            out.append("```text\n" + para + "\n```")
        else:
            out.append(" ".join(ln.strip() for ln in lines))
    return "\n\n".join(out)


def _cell(kind: str, cid: str, source: str, tags: list[str] | None = None) -> dict:
    lines = source.splitlines(keepends=True)
    cell = {"cell_type": kind, "id": cid, "metadata": {"tags": tags} if tags else {}, "source": lines}
    return cell | (dict(execution_count=None, outputs=[]) if kind == "code" else {})


def build_notebook(script: Path = SCRIPT) -> str:
    """The notebook JSON text: deterministic (fixed ids, no timestamps, no outputs)."""
    regions = parse_regions(script)
    title, _, rest = module_docstring(script).partition("\n")
    intro = (
        f"# {title.strip()}\n\n{_prose(rest)}\n\n"
        f"*Built from `{Path(script).name}` by `python -m tools.notebook`: one section per region of the "
        "script. Edit the script, not this notebook.*"
    )
    argv = ARGV_CELL.format(cache_note=CACHE_NOTE if supports_flag(script, "--cache") else "")
    cells = [
        _cell("markdown", "intro", intro),
        _cell("code", "install", INSTALL_CELL, ["install"]),
        _cell("code", "argv", argv, ["argv"]),
    ]
    for i, r in enumerate(regions, 1):
        cells.append(_cell("markdown", f"{r.name}-md", f"## {i}. {r.name}\n\n{' '.join(r.intent)}"))
        cells.append(_cell("code", f"{r.name}-code", r.code, [f"region-{r.name}"]))
        if r.name == "emit":  # after the emit region: the poster it wrote, inline
            cells.append(_cell("code", "poster", POSTER_CELL, ["poster"]))
    kernel = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
    meta = {"colab": {"provenance": [], "toc_visible": True}, "kernelspec": kernel}
    meta["language_info"] = {"name": "python"}
    nb = {"cells": cells, "metadata": meta, "nbformat": 4, "nbformat_minor": 5}
    # not ch37.ownership.dump_json: a notebook keeps its text UTF-8 as is, as nbformat writes it
    return json.dumps(nb, indent=1, sort_keys=True, ensure_ascii=False) + "\n"


def main(argv: list[str]) -> int:
    p = parser("notebook", __doc__)
    p.add_argument("--check", action="store_true", help="exit 1 if the notebook does not match the script")
    p.add_argument("--out", type=Path, default=NOTEBOOK, help="default scale_data.ipynb")
    a = p.parse_args(argv)
    text = build_notebook(a.script)
    if a.check:
        if not a.out.exists() or a.out.read_text(encoding="utf-8") != text:
            print(f"stale: {rel(a.out)} does not match {rel(a.script)}; run: python -m tools.notebook")
            return 1
        print(f"ok: {rel(a.out)} matches {rel(a.script)}")
        return 0
    write_atomic(a.out, text)
    print(f"wrote {rel(a.out)}")
    return 0


if __name__ == "__main__":
    errors.main(main)
