"""The posters (ch37.poster): scale_data.html and scale_lab.html, self-contained and deterministic,
rendered in a real headless Chromium where one is installed (run_tests.sh installs Debian's chromium
as root with apt-get).

The pages hold no script, so what Chromium shows here is what a reader with JavaScript off sees."""

import html
import json
import re
import shutil
import subprocess

import numpy as np
import pytest
import yaml
from conftest import ROOT, run_script

from ch37 import poster

CHROMIUM = next(filter(None, map(shutil.which, ("chromium", "chromium-browser", "google-chrome"))), None)
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None,
    reason="Chromium is not installed (Debian: apt-get install chromium; run_tests.sh installs it as root)",
)
WIDTHS = {"laptop": (1200, 900), "phone": (390, 844)}


def smoke(out):
    return run_script("scale_data.py", "--smoke", "--seed", "0", "--no-rerun", "--no-cache", "--out", out)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two smoke runs with the same flags in separate folders."""
    a, b = tmp_path_factory.mktemp("a"), tmp_path_factory.mktemp("b")
    p = smoke(a)
    smoke(b)
    return p, a, b


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """One smoke Scale Lab at one seed (half the smoke lab's work): its folder."""
    out = tmp_path_factory.mktemp("lab") / "out"
    run_script(ROOT / "scale_lab.py", "--smoke", "--seeds", "0", "--no-rerun", "--out", out)
    return out


def text_of(markup: str) -> str:
    """What a reader sees (and a screen reader reads): tags dropped, entities decoded, spaces collapsed."""
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", markup)).split())


def assert_self_contained(page: str) -> None:
    assert "<script" not in page.lower() and "javascript:" not in page.lower()
    assert not re.search(r"https?://", page)  # nothing fetched, not even a namespace URL
    assert not re.search(r"\b(src|href|xlink:href|srcset|action)\s*=", page, re.I)
    assert "@import" not in page and "url(" not in page


def chapter_numbers(out) -> list[str]:
    """The run's numbers as the page must print them, from its metrics.json and cross_embodiment.json."""
    m = json.loads((out / "metrics.json").read_text())
    cross = json.loads((out / "cross_embodiment.json").read_text())
    arms, b, cov = m["arms"], m["budgets"], m["coverage"]
    want = [
        f"At equal steps ({b['full']:,} each), source only {arms['source_full']['success']:.2f} → source + "
        f"augmented {arms['augmented_full']['success']:.2f} ({m['effects']['data_full'] * 100:+.0f} points)",
        f"Coverage {cov['source']} → {cov['union']} of {cov['cells']} cells",
        f"kept {m['kept']} of {m['attempts']} attempts (yield {m['yield']:.2f})",
        f"{b['short']:,} steps each",
        f"{b['full']:,} steps each",
        f"seed {m['seed']}",
    ]
    for arm in arms.values():  # every bar's rate and interval, in the figure's description
        label = poster.DATA_LABEL[arm["data"]]
        lo, hi = arm["ci95"]
        want.append(
            f"{label} at the {arm['budget']} budget {arm['success']:.2f} (95% interval {lo:.2f} to {hi:.2f})"
        )
    pad = cross["padded_action_dim"]
    want += [f"{poster.NAMES[e['name']]} {e['act_dim']} of {pad} real" for e in cross["embodiments"]]
    return want


def test_two_smoke_runs_write_the_same_self_contained_poster(runs):
    p, a, b = runs
    page = (a / "scale_data.html").read_text(encoding="utf-8")
    assert page.encode() == (b / "scale_data.html").read_bytes()
    assert "scale_data.html" in p.stdout.strip().splitlines()[-1]  # the last line says where it is
    assert_self_contained(page)
    text = text_of(page)
    for want in chapter_numbers(a):
        assert want in text, want
    assert "PushT 2 of 6 real" in text and "ALOHA 6 of 6 real" in text  # the smoke run's two robots
    assert page.count("<title") == 3 and page.count("<desc") == 2  # the page, the annulus, the bars


def test_the_lab_poster_is_a_pure_function_of_its_json(lab):
    page = (lab / "scale_lab.html").read_text(encoding="utf-8")
    result = json.loads((lab / "scale_lab.json").read_text())
    result["seconds"] = {"total": 1e9, "train": 1e9}  # wall time differs run to run; the page must not
    assert poster.lab_html(result) == page
    assert_self_contained(page)
    text = text_of(page)
    assert f"the expert's own success is {result['expert']['success']:.2f}" in text
    assert result["command"] in text
    for curve, rows in result["curves"].items():  # every point of the table, as the page prints it
        for n, r in rows.items():
            assert f"{r['success']:.3f} [{r['ci95'][0]:.3f}, {r['ci95'][1]:.3f}]" in text, (curve, n)
    for question in (
        "Where the curve bends.",
        "The exchange rate.",
        "Data or compute.",
        "How far from the expert.",
    ):
        assert question in text


def test_the_lab_answers_read_the_published_curves_as_the_readme_does():
    """meta.yaml's scale_lab section (written by tools.meta from the default lab's JSON), read by the
    poster: the README's exchange rates (108, 324, 972 re-solved demos match about 74, 207 and 459 fresh
    ones, worth 0.65, 0.62, 0.47 each) and its bend (36 -> 108)."""
    meta = yaml.safe_load((ROOT / "meta.yaml").read_text())["scale_lab"]
    result = {
        "config": {"sources": 12},
        "curves": {c: {str(n): r for n, r in rows.items()} for c, rows in meta["curves"].items()},
    }
    got = {r["n"]: r for r in poster.exchange_rows(result) if r["curve"] == "resolve"}
    assert [round(got[n]["fresh"]) for n in (108, 324, 972)] == [74, 207, 459]
    assert [round(got[n]["worth"], 2) for n in (108, 324, 972)] == [0.65, 0.62, 0.47]
    assert "bend at N = <b>36</b>" in poster.answer_bend(result)
    assert poster.matched_fresh(result, 2.0) is None  # above every fresh point: not read off the curve


def test_the_headline_places_the_default_seed_beside_the_five_seed_reference(runs):
    """Issue 33 #8: for the swept configuration, the poster and the printed headline say where this seed
    stands among meta.yaml's five (mean, range, seeds up); another configuration is not compared."""
    from ch37 import cli

    seeds = yaml.safe_load((ROOT / "meta.yaml").read_text())["reference_run"]["seeds"]
    default = dict(seeds["provenance"]["config"], seed=0, aug_mode="resolve", aug_tries=100, rerun=True)
    ref = cli.five_seed_reference(default)
    assert ref["effects"] == {r["seed"]: r["data_full"] for r in seeds["rows"]}
    assert (ref["mean"], ref["up"], ref["n"]) == (seeds["paired"]["data_full"]["mean"], 5, 5)
    lo, hi = min(ref["effects"].values()), max(ref["effects"].values())
    words = cli.reference_words(ref, 0, hi)  # this run's own effect is what is placed, not seed 0's
    summary = (
        f"mean {ref['mean'] * 100:+.1f} over seeds 0, 1, 2, 3, 4, from {lo * 100:+.0f} to {hi * 100:+.0f}"
    )
    assert summary in words and "python -m tools.sweep --seeds 5" in words
    # issue 60 #6: placed among the other four seeds (not counting seed 0 itself), above as well as below
    assert "among the other seeds (1, 2, 3, 4) this run's effect is tied with 1, above 3" in words
    assert "this run's effect is below 4" in cli.reference_words(ref, 0, lo - 0.02)
    assert "this run's effect is below 2, tied with 1, above 1" in cli.reference_words(ref, 0, 0.08)
    assert "not this one" in cli.reference_words(None, 0, 0.1)  # another configuration: said so
    for other in ({"aug_mode": "replay"}, {"pusht_data": "big"}, {"epochs": 499}, {"smoke": True}):
        assert cli.five_seed_reference(dict(default, **other)) is None, other
    _, a, _ = runs  # a smoke run: no reference on its page or in its headline
    m = json.loads((a / "metrics.json").read_text())
    assert cli.five_seed_reference(m["config"]) is None
    cross = json.loads((a / "cross_embodiment.json").read_text())
    page = poster.chapter_html(m, cross, np.zeros((0, 2)), np.zeros((0, 2)), (0.1, 0.24, 3, 12), words)
    assert f"One seed is one draw: {words}." in text_of(page)
    assert "five-seed reference" not in (a / "scale_data.html").read_text(encoding="utf-8")


def chromium(tmp_path, *args) -> subprocess.CompletedProcess:
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars"]
    profile = f"--user-data-dir={tmp_path / 'profile'}"  # a private profile: runs side by side never collide
    return subprocess.run(
        [CHROMIUM, *flags, profile, *map(str, args)], capture_output=True, text=True, timeout=180
    )


def screenshot_colours(tmp_path, page, size) -> dict:
    """Render `page` at `size` (width, height); the PNG's size, distinct colours and pixels near the
    source blue and the augmented orange."""
    from PIL import Image

    png = tmp_path / f"shot_{size[0]}.png"
    p = chromium(tmp_path, f"--screenshot={png}", f"--window-size={size[0]},{size[1]}", page.as_uri())
    assert png.exists(), p.stderr[-2000:]
    im = np.asarray(Image.open(png).convert("RGB"), dtype=np.int16)  # (height, width, 3)

    def near(rgb):  # pixels within 24 of a colour on every channel
        return int((np.abs(im - np.array(rgb)) <= 24).all(axis=2).sum())

    colours = len(np.unique(im.reshape(-1, 3), axis=0))
    return {
        "size": im.shape[1::-1],
        "colours": colours,
        "blue": near((31, 119, 180)),
        "orange": near((255, 127, 14)),
    }


@needs_chromium
@pytest.mark.parametrize("width", WIDTHS)
def test_chromium_renders_the_poster_with_its_numbers(runs, tmp_path, width):
    _, a, _ = runs
    page = a / "scale_data.html"
    shot = screenshot_colours(tmp_path, page, WIDTHS[width])
    assert shot["size"] == WIDTHS[width]
    assert shot["colours"] > 50, shot  # not blank: text, figures, swatches
    assert shot["blue"] > 100 and shot["orange"] > 50, shot  # the source and augmented marks were drawn
    dom = chromium(tmp_path, "--dump-dom", page.as_uri())
    text = text_of(dom.stdout)
    for want in chapter_numbers(a):
        assert want in text, want


@needs_chromium
def test_chromium_renders_the_lab_poster(lab, tmp_path):
    page = lab / "scale_lab.html"
    for size in WIDTHS.values():
        shot = screenshot_colours(tmp_path, page, size)
        assert shot["size"] == size and shot["colours"] > 50 and shot["blue"] > 50, shot
    text = text_of(chromium(tmp_path, "--dump-dom", page.as_uri()).stdout)
    result = json.loads((lab / "scale_lab.json").read_text())
    assert f"the expert's own success is {result['expert']['success']:.2f}" in text
