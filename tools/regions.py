"""The five regions of scale_data.py: their hashes (see tools.common), compared with meta.yaml.

    python -m tools.regions            each region: name, line range, sha256
    python -m tools.regions --check    exit 1 naming every region that drifted from meta.yaml
    python -m tools.regions --write    refresh meta.yaml's region_hashes (nothing else)

Exit codes: 0 ok, 1 drift, 2 bad input (a missing file, malformed markers, bad flags).
"""

from __future__ import annotations

from pathlib import Path

from ch37 import errors
from tools.common import META, drifted, parse_regions, parser, region_hashes, rel
from tools.meta import META_STATIC, load_yaml, write_meta


def main(argv: list[str]) -> int:
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
    current, meta = region_hashes(a.script), load_yaml(a.meta)
    if a.write:
        meta["region_hashes"] = current
        write_meta(a.meta, meta if meta.get("id") else {**META_STATIC, **meta})
        print(f"wrote region_hashes of {rel(a.script)} to {rel(a.meta)}")
        return 0
    if not meta.get("region_hashes"):
        print(f"drift: {rel(a.meta)} has no region_hashes; run: python -m tools.regions --write")
        return 1
    if bad := drifted(current, meta["region_hashes"]):
        print(
            f"drift: region(s) {', '.join(bad)} of {rel(a.script)} differ from {rel(a.meta)} "
            "region_hashes; if the change is intended, run: python -m tools.regions --write "
            "(and re-run the sweeps + python -m tools.meta if the numbers may have moved)"
        )
        return 1
    print(f"ok: all {len(current)} regions match {rel(a.meta)}")
    return 0


if __name__ == "__main__":
    errors.main(main)
