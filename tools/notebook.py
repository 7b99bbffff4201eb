"""scale_data.ipynb from the regions of scale_data.py: one markdown and one code cell per region.

    python -m tools.notebook            write scale_data.ipynb
    python -m tools.notebook --check    exit 1 if scale_data.ipynb does not match the script

The notebook is deterministic (fixed cell ids, no timestamps, no outputs), so --check is a byte
comparison. Edit the script, not the notebook. Its first cell clones the course repository from
pyproject.toml's [project.urls] Repository (copied in at build time: a notebook opened alone has no
pyproject.toml); without that entry (not published yet) the cell says so in one line and stops.

Exit codes: 0 ok, 1 stale notebook, 2 bad input (malformed markers, bad flags).
"""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path

from ch37 import ROOT, errors
from ch37.ownership import write_atomic
from tools.common import NOTEBOOK, SCRIPT, module_docstring, parse_regions, parser, rel, supports_flag

# The course repository's git address: pyproject.toml's [project.urls] Repository, its one home. Copied
# into the install cell at build time, since a notebook opened alone (Colab) has no pyproject.toml.
URL_KEY = "Repository"
INSTALL_CELL = """\
# The course's code and packages: run this cell first (Run all does). Opened alone (Colab, a fresh
# runtime), this notebook clones the course repository beside itself and moves into it; opened from a
# clone, it finds it. Then pip installs the course's packages unless lerobot is importable already,
# keeping every preinstalled package that satisfies the course's pins; one line says what the install
# changed and whether to restart the runtime. Safe to run again.
import os
import subprocess
import sys
from pathlib import Path

# the repository's address: {where}
REPO_URL = {url!r}{unset}


class Stop(Exception):
    \"\"\"Stops Run all with one line and no traceback (IPython shows what _render_traceback_ returns).\"\"\"

    def _render_traceback_(self):
        return [f"stopped: {{self}}"]


def find_repo(here):
    \"\"\"The course repository: this folder, or one folder below it (a clone beside the notebook).\"\"\"
    found = [here, *sorted(p.parent for p in here.glob("*/scale_data.py"))]
    return next((d for d in found if (d / "scale_data.py").is_file() and (d / "tools").is_dir()), None)


here = Path.cwd()
repo = find_repo(here)
if repo is None and REPO_URL is None:
    raise Stop(
        "the course repository is not published yet, so this notebook has no address to clone it from: "
        f"put a copy of its folder in {{here}} and run this cell again"
    )
if repo is None:
    repo = here / REPO_URL.rstrip("/").rsplit("/", 1)[-1].removesuffix(".git")
    print(f"cloning {{REPO_URL}} into {{repo}}", flush=True)
    clone = ["git", "clone", "--quiet", "--depth", "1", REPO_URL, str(repo)]
    got = subprocess.run(clone, capture_output=True, text=True)
    if got.returncode != 0:
        why = (got.stderr.strip().splitlines() or [f"exit {{got.returncode}}"])[-1]
        raise Stop(f"git clone {{REPO_URL}} failed: {{why}}")
os.chdir(repo)
if str(repo) not in sys.path:
    sys.path.insert(0, str(repo))
from tools.install import ensure_packages

print(f"repository {{repo}}; {{ensure_packages(repo)}}")"""

ARGV_CELL = """\
# The run's flags, as scale_data.py takes them on its command line: edit this cell, then Run all. Every
# flag, with its unit and default: run  !{{sys.executable}} scale_data.py --help  in a cell.
{cache_note}import sys

SMOKE = False  # True: the smoke run (a tiny configuration, seconds; its numbers are not meaningful)
sys.argv = ["scale_data.py", "--seed", "0"{no_cache}] + (["--smoke"] if SMOKE else [])"""
FIGURE_CELL = """\
# The figure this run wrote, scale_data.png: block starts over the spawn annulus, and the 2x2's bars.
from IPython.display import Image

Image(filename=str(args.out / "scale_data.png"))"""
POSTER_CELL = """\
# The poster this run wrote beside its PNG: scale_data.html, one self-contained page (inline SVG and
# CSS, no script, nothing fetched), shown here inline. The file opens in any browser, shared as is.
from IPython.display import HTML

HTML((args.out / "scale_data.html").read_text(encoding="utf-8"))"""
RERUN_CELL = """\
# The Rerun recording this run wrote, scale_data.rrd (the data-scale curve, block-start coverage, a few
# augmented trajectories), shown below in Rerun's notebook viewer (rerun-notebook, among the course's
# packages): the kernel hands the file's bytes to the viewer's widget, which plays them in the browser.
# The viewer's own code (JavaScript and WebAssembly, 67 MB installed) is not sent by the kernel: by
# default the browser loads it from app.rerun.io, which needs the browser online (Colab is). Offline,
# have it served from the installed package instead: RERUN_NOTEBOOK_ASSET=inline (the code goes into the
# widget, about 23 MB the kernel sends to the browser) or serve-local (a server in the kernel on localhost,
# which the browser must reach: a local Jupyter, not Colab), set before this cell first runs in the
# kernel (it is read once): restart the kernel, run  %env RERUN_NOTEBOOK_ASSET=inline  in a cell, Run all.
# Rerun's desktop viewer opens the file too (pip install rerun-sdk, then: rerun scale_data.rrd).
import importlib.util

from IPython.display import display

rrd = (args.out / "scale_data.rrd").resolve()
if not args.rerun or not rrd.is_file():
    print(
        "no recording: this run had --no-rerun (without it, the run writes scale_data.rrd, shown here; "
        "Rerun's desktop viewer opens it too: rerun scale_data.rrd)"
    )
elif importlib.util.find_spec("rerun_notebook") is None:
    print(
        f"recording: {rrd} ({rrd.stat().st_size / 1e6:.1f} MB), not shown: Rerun's notebook viewer "
        f"(rerun-notebook) is not installed; open the file with Rerun's desktop viewer: rerun {rrd}"
    )
else:
    import rerun_notebook

    print(f"recording: {rrd} ({rrd.stat().st_size / 1e6:.1f} MB), in Rerun's notebook viewer below")
    # rerun.notebook.Viewer shows what a live recording logs; its widget, rerun_notebook.Viewer, takes
    # a .rrd file's bytes as they are, kept in the kernel until the viewer has loaded in the browser
    viewer = rerun_notebook.Viewer(width="auto", height=640)
    viewer.send_rrd(rrd.read_bytes())
    display(rerun_notebook.ErrorWidget(), viewer)  # the first says so if the viewer's code cannot load"""
CACHE_NOTE = """\
# --no-cache: every Run all really runs the chapter, a second one too. Without it an identical earlier
# run is replayed from the result cache and the setup cell stops the notebook there ("SystemExit: 0").
"""
NOTEBOOK_INTRO = """\
**In this notebook.** The first cell gets the course's code and packages; the second holds the run's \
flags, the one cell to edit before Run all (`SMOKE = True` runs the seconds-long smoke configuration). \
The five sections after it are the five regions of `scale_data.py`, the lesson, cell for cell: change \
one to experiment and run again; Run all again reruns the whole chapter. The exercises' files are in \
the repository's folder, `exercises/` (on Colab: the Files panel).

*Course maintainers: this notebook is built from `{script}` by `python -m tools.notebook`; \
edit the script and rebuild it.*"""


def repository_url(pyproject: Path = ROOT / "pyproject.toml") -> str | None:
    """pyproject.toml's [project.urls] Repository: where the notebook clones the course from; None while the
    repository is not published (no entry)."""
    try:
        urls = tomllib.loads(Path(pyproject).read_text(encoding="utf-8")).get("project", {}).get("urls", {})
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise errors.DataError(f"{rel(pyproject)}: {e}") from None
    url = urls.get(URL_KEY)
    if url is not None and (not isinstance(url, str) or not url.strip() or "\n" in url):
        raise errors.DataError(f"{rel(pyproject)}: [project.urls] {URL_KEY} must be the repository's address")
    return url


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


def _docstring_for_notebook(text: str) -> str:
    """The script's docstring less its command lines (Run:, Smoke:): a notebook runs it with Run all."""
    return "\n".join(ln for ln in text.splitlines() if not re.match(r"(Run|Smoke):\s", ln))


def build_notebook(script: Path = SCRIPT, repo_url: str | None = ...) -> str:
    """The notebook JSON text: deterministic (fixed ids, no timestamps, no outputs). repo_url: the address
    the install cell clones from (default: pyproject.toml's, repository_url)."""
    url = repository_url() if repo_url is ... else repo_url
    regions = parse_regions(script)
    title, _, rest = module_docstring(script).partition("\n")
    intro = f"# {title.strip()}\n\n{_prose(_docstring_for_notebook(rest))}\n\n"
    intro += NOTEBOOK_INTRO.format(script=Path(script).name)
    where = f"pyproject.toml's [project.urls] {URL_KEY}, copied here by python -m tools.notebook"
    unset = "  # None: not published yet" if url is None else ""
    install = INSTALL_CELL.format(url=url, where=where, unset=unset)
    cache = supports_flag(script, "--cache")
    no_cache = ', "--no-cache"' if cache else ""
    argv = ARGV_CELL.format(cache_note=CACHE_NOTE if cache else "", no_cache=no_cache)
    cells = [
        _cell("markdown", "intro", intro),
        _cell("code", "install", install, ["install"]),
        _cell("code", "argv", argv, ["argv"]),
    ]
    for i, r in enumerate(regions, 1):
        cells.append(_cell("markdown", f"{r.name}-md", f"## {i}. {r.name}\n\n{' '.join(r.intent)}"))
        cells.append(_cell("code", f"{r.name}-code", r.code, [f"region-{r.name}"]))
        if r.name == "emit":  # after the emit region: what it wrote, inline
            cells.append(_cell("code", "figure", FIGURE_CELL, ["figure"]))
            cells.append(_cell("code", "poster", POSTER_CELL, ["poster"]))
            cells.append(_cell("code", "rerun", RERUN_CELL, ["rerun"]))
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
