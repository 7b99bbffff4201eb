"""The published numbers, reproduced: scale_data.py's default configuration at seed 0 gives meta.yaml's
seed-0 row exactly (every arm's successes, both budgets' steps, the augmentation's counts) wherever it
runs on the published kernel path: an x86-64 CPU with AVX2 and FMA, the training's products on numpy's
OpenBLAS held to its Haswell kernels and MKL held to one branch, both by the setup region
(docs/reproducibility.md). A learner's `bash run_chapter.sh` prints this row. Not slow-marked: CI runs
it (a default run, about 2-3 minutes on 2 cores)."""

import json
import os
import platform

import pytest
import yaml
from conftest import ROOT, run_script

from ch37 import cli
from ch37.process import has_avx2_fma
from exercises.rules import ARMS


@pytest.mark.skipif(
    not has_avx2_fma(), reason="the published kernel path needs an x86-64 CPU with AVX2 and FMA"
)
@pytest.mark.skipif(
    os.environ.get("MKL_CBWR", cli.PUBLISHED_MKL_CBWR) != cli.PUBLISHED_MKL_CBWR
    or os.environ.get("OPENBLAS_CORETYPE", cli.PUBLISHED_BLAS_CORE) != cli.PUBLISHED_BLAS_CORE,
    reason="MKL_CBWR or OPENBLAS_CORETYPE names other kernels in this environment: another draw, by design",
)
def test_the_default_run_at_seed_0_is_meta_yamls_seed_0_row(tmp_path):
    row = next(r for r in yaml.safe_load((ROOT / "meta.yaml").read_text())["reference_run"]["seeds"]["rows"])
    assert row["seed"] == 0
    p = run_script("scale_data.py", "--seed", "0", "--no-rerun", "--no-cache", "--out", tmp_path)
    m = json.loads((tmp_path / "metrics.json").read_text())
    n = m["config"]["eval_episodes"]
    got = {arm: round(m["arms"][arm]["success"] * n) for arm in ARMS}
    assert (got, m["budgets"], n) == (row["successes"], row["steps"], row["eval_episodes"]), (
        f"this host ({platform.processor() or platform.machine()}) did not reproduce meta.yaml's seed-0 "
        f"row: {got} {m['budgets']} against {row['successes']} {row['steps']}"
    )
    assert (m["kept"], m["attempts"], m["coverage"]["union"]) == (
        row["kept"],
        row["attempts"],
        row["coverage_union"],
    )
    assert "another draw" not in p.stdout  # the banner knows this run is on the published path
    assert "this run's effect is" in p.stdout  # the closing lines place it among the reference's five
