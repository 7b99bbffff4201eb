"""The posters: one self-contained HTML page per run, readable with JavaScript off.

    chapter(path, metrics, cross, src_starts, aug_starts, annulus)   scale_data.html
    lab(path, result)                                                 scale_lab.html

Inline SVG and CSS only, nothing fetched: a page opens the same offline, as one file, or in the notebook
(its CSS is scoped to .poster). No date, and the dicts pass the JSON files' rounding, so the same flags
write the same bytes. Every figure has a <title> and <desc> for screen readers. The Scale Lab's four
answers are read off its curves here (log-linear between measured points).
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

from ch37 import ROOT
from ch37.ownership import dump_json, round_floats, write_atomic
from ch37.viz import DATA_COLOURS, DATA_LABEL, LAB_DEFAULT, LAB_STYLE

HEX = {"tab:blue": "#1f77b4", "tab:orange": "#ff7f0e", "tab:green": "#2ca02c", "tab:red": "#d62728"}
NAMES = {"pusht": "PushT", "aloha": "ALOHA"}  # embodiment names as the chapter writes them
# objective 2, measured: python -m tools.embodiment's kept run; the chapter poster's strip shows it, so
# it is part of the result cache's key (READS, ch37.code_files): a new kept run is a new poster
EMBODIMENT = ROOT / "results" / "embodiment.json"
READS = (EMBODIMENT,)
GROWN_BY = {"resolve": "re-solving", "replay": "replay"}
DATA_VAR = {"source": "var(--src)", "augmented": "var(--aug)"}  # the arms' colours, set in CSS
BUDGET_ORDER = ("short", "full")
SHORT = dict(fresh="fresh", resolve="re-solve", replay="replay", resolve_fixed="re-solve, fixed budget")
DASH = {"-": {}, "-.": {"stroke_dasharray": "9 4 2 4"}}  # matplotlib line style -> SVG dashes
QUESTIONS = ("Where the curve bends.", "The exchange rate.", "Data or compute.", "How far from the expert.")
STAR = '<span aria-hidden="true">&#9733;</span> '  # the default point's legend mark; the SVG has its own
SMOKE = (
    '<p class="note">Smoke run: a tiny configuration that checks the pipeline in seconds; its numbers are \
not meaningful.</p>\n'
)
FONT = 'system-ui,-apple-system,"Segoe UI",Roboto,"Liberation Sans",Arial,sans-serif'
# SVG text sizes are classes (tk ticks, vl values, gl/gs group labels) so a phone can show them larger
CSS = """\
.poster{--src:%(src)s;--aug:%(aug)s;--real:#2a7d62;--ink:#1b1b1b;--muted:#555;--line:#d4d4d4;color:var(--ink);
 background:#fff;font:16px/1.45 %(font)s;max-width:1120px;margin:0 auto;padding:20px 16px 28px;
 -webkit-text-size-adjust:100%%}
.poster *{box-sizing:border-box} .poster p{margin:.35rem 0} .poster ol{padding-left:1.3em;margin:.3rem 0}
.poster h1{font-size:1.6rem;line-height:1.2;margin:.1rem 0 .5rem} .poster li{margin:.35rem 0}
.poster h2{font-size:1.05rem;line-height:1.3;margin:0 0 .4rem} .poster .scroll{overflow-x:auto}
.poster .kicker{font-size:.85rem;color:var(--muted);letter-spacing:.02em;margin:0}
.poster .headline{font-size:1.25rem;line-height:1.35;margin:.2rem 0 .5rem}
.poster b{font-weight:700;font-variant-numeric:tabular-nums}
.poster .row{display:flex;flex-wrap:wrap;gap:16px;margin:16px 0} .poster .note{background:#fff5d9;
 border:1px solid #e5c66b;border-radius:6px;padding:.35rem .6rem;font-size:.9rem}
.poster figure{margin:0;flex:1 1 360px;min-width:0;background:#fafafa;border:1px solid var(--line);
 border-radius:10px;padding:12px 14px} .poster figure.square{flex:1 1 300px;max-width:480px}
.poster figure.wide{flex-basis:100%%} .poster figcaption{font-size:.9rem;color:var(--muted);margin-top:.5rem}
.poster svg{display:block;width:100%%;height:auto;max-width:100%%} .poster svg.lab{max-width:820px;
 margin:0 auto} .poster svg text{font-family:%(font)s;fill:var(--ink)}
.poster svg .tk{font-size:13px} .poster svg .vl{font-size:13px;font-weight:700}
.poster svg .gl{font-size:14px;font-weight:700} .poster svg .gs{font-size:12.5px}
.poster .legend{display:flex;flex-wrap:wrap;gap:2px 16px;list-style:none;padding:0;margin:0 0 .4rem;
 font-size:.9rem} .poster .sw{display:inline-block;width:.85em;height:.85em;margin-right:.35em;
 vertical-align:-.08em;border-radius:2px} .poster .sw.dot{border-radius:50%%}
.poster .sw.dash{height:0;border-top:3px dashed #444;border-radius:0;vertical-align:.2em}
.poster .strip{display:grid;grid-template-columns:10em repeat(6,minmax(0,1fr));gap:5px;align-items:stretch;
 margin:.3rem 0} .poster .strip .who{align-self:center;font-size:.95rem;line-height:1.3}
.poster .strip .who small{display:block;color:var(--muted);font-size:.8rem}
.poster .dim{border-radius:6px;padding:7px 3px;font-size:.8rem;line-height:1.2;text-align:center;
 overflow-wrap:anywhere;min-height:3.2em;display:flex;flex-direction:column;justify-content:center}
.poster .dim small{display:block;font-size:.75rem;opacity:.85} .poster .dim.real{background:var(--real);
 color:#fff} .poster .dim.pad{background:repeating-linear-gradient(135deg,#ececec 0 6px,#dcdcdc 6px 12px);
 color:#666} .poster table{border-collapse:collapse;font-size:.88rem;font-variant-numeric:tabular-nums}
.poster th,.poster td{padding:4px 12px 4px 0;border-bottom:1px solid var(--line);text-align:left;
 vertical-align:top} .poster table.points td small{display:block;color:var(--muted);white-space:nowrap}
.poster footer{font-size:.85rem;color:var(--muted);border-top:1px solid var(--line);padding-top:10px;
 margin-top:18px} .poster code{font-family:ui-monospace,"DejaVu Sans Mono",Menlo,Consolas,monospace;
 font-size:.85em;overflow-wrap:anywhere}
.poster .cfg{display:flex;flex-wrap:wrap;gap:4px 6px;list-style:none;padding:0;margin:.4rem 0}
.poster .cfg li{background:#efefef;border-radius:4px;padding:1px 6px;margin:0}
@media (max-width:560px){
 .poster{padding:12px 10px 20px} .poster h1{font-size:1.3rem} .poster .headline{font-size:1.08rem}
 .poster figure{padding:10px 8px} .poster .strip{grid-template-columns:repeat(6,minmax(0,1fr))}
 .poster .strip .who{grid-column:1/-1;margin-top:.3rem} .poster .dim{font-size:.7rem}
 .poster svg.lab .tk{font-size:21px} .poster svg.lab .ylab,.poster svg.bars .ylab{display:none}
 .poster svg.bars .tk,.poster svg.bars .gs{font-size:15px} .poster svg.bars .vl{font-size:16px}
 .poster svg.bars .gl{font-size:17px} .poster table{font-size:.82rem} .poster th,.poster td{padding-right:7px}
 .poster table.points td small{white-space:normal}
}
""" % {"src": HEX[DATA_COLOURS["source"]], "aug": HEX[DATA_COLOURS["augmented"]], "font": FONT}


def _as_written(obj):
    """The dict as its JSON file holds it, so the page shows what the file says, not the caller's memory."""
    return json.loads(dump_json(round_floats(obj, 6)))


def _c(x: float) -> str:
    """An SVG coordinate to 0.1 unit: short, stable text (never '-0.0')."""
    s = f"{x:.1f}"
    return "0.0" if s == "-0.0" else s


def _e(text) -> str:
    return html.escape(str(text), quote=True)


def _el(tag: str, text=None, **attrs) -> str:
    """One element. Floats are coordinates (_c), a list of (x, y) is points; a list of children goes one
    a line; an attribute's _ is written - (class_ is class), as Python names cannot hold one."""
    for k, v in attrs.items():
        v = " ".join(f"{_c(a)},{_c(b)}" for a, b in v) if isinstance(v, list) else v
        attrs[k] = _c(v) if isinstance(v, float) else v
    a = "".join(f' {k.rstrip("_").replace("_", "-")}="{v}"' for k, v in attrs.items())
    text = "\n".join(["", *text, ""]) if isinstance(text, list) else text
    return f"<{tag}{a}/>" if text is None else f"<{tag}{a}>{text}</{tag}>"


def _svg(uid: str, width: int, height: int, title: str, desc: str, body: list[str]) -> str:
    head = [_el("title", _e(title), id=f"{uid}-t"), _el("desc", _e(desc), id=f"{uid}-d")]
    box, labels = f"0 0 {width} {height}", f"{uid}-t {uid}-d"
    return "\n" + _el("svg", head + body, class_=uid, viewBox=box, role="img", aria_labelledby=labels)


def _axes(x0: int, x1: int, top: int, bot: int):
    """y(success) -> SVG y, and the body's start: gridlines at 0, 0.25 .. 1 with their values, and the
    y label (a phone's CSS hides it)."""

    def y(v):
        return float(bot - v * (bot - top))

    vs, mid = (0, 0.25, 0.5, 0.75, 1), (top + bot) // 2
    ticks = [_el("line", x1=x0, x2=x1, y1=y(v), y2=y(v)) for v in vs]
    ticks += [_el("text", f"{v:g}", x=x0 - 6, y=y(v) + 4, stroke="none") for v in vs]
    rotate = f"rotate(-90 14 {mid})"
    label = _el("text", "success rate", class_="tk ylab", x=14, y=mid, text_anchor="middle", transform=rotate)
    return y, [_el("g", ticks, class_="tk", stroke="#ddd", text_anchor="end"), label]


def _sw(colour: str = "", cls: str = "sw") -> str:
    """A legend swatch: a square of `colour` (a dot, a dash by class)."""
    return f'<span class="{cls}"' + (f' style="background:{colour}"' if colour else "") + "></span>"


def _legend(items) -> str:
    return '<ul class="legend">' + "".join(f"<li>{sw}{label}</li>" for sw, label in items) + "</ul>"


def _doc(title: str, body: str, note: str, config: dict) -> str:
    """The page around `body`; the footer's `note` names the run and its sources, then its configuration."""
    cfg = "".join(f"<li><code>{_e(k)} {_e(json.dumps(v))}</code></li>" for k, v in sorted(config.items()))
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        f'<title>{_e(title)}</title>\n<style>\n{CSS}</style>\n</head>\n<body style="margin:0">\n'
        f'<main class="poster">\n{body}\n<footer>\n<p>{note} Configuration:</p>\n'
        f'<ul class="cfg" aria-label="configuration">{cfg}</ul>\n</footer>\n</main>\n</body>\n</html>\n'
    )


def _pts(x: float) -> str:  # a success difference in percentage points, as scale_data.py prints it
    return f"{x * 100:+.0f}"


# --- scale_data.html -------------------------------------------------------------------------------
def _coverage_svg(src_starts, aug_starts, cov: dict, annulus) -> str:
    """Block starts over the spawn annulus: rings and sectors, source squares, kept dots, the target."""
    r_min, r_max, rings, sectors = annulus
    size, mid = 320, 160
    scale = mid / (r_max * 1.2)  # SVG units per metre; the keep band (a little past r_max) fits

    def xy(p):  # metres from the target -> SVG units (y points down)
        return mid + float(p[0]) * scale, mid - float(p[1]) * scale

    radii = [(r_min + (r_max - r_min) * i / rings) * scale for i in range(rings + 1)]
    grid = [_el("circle", cx=mid, cy=mid, r=r) for r in radii]
    for th in (2 * math.pi * j / sectors for j in range(sectors)):
        (a, b), (c, d) = (xy((r * math.cos(th), r * math.sin(th))) for r in (r_min, r_max))
        grid.append(_el("line", x1=a, y1=b, x2=c, y2=d))
    aug = [_el("circle", cx=x, cy=y, r=3) for x, y in map(xy, aug_starts)]
    src = [_el("rect", x=x - 5, y=y - 5, width=10, height=10) for x, y in map(xy, src_starts)]
    body = [
        _el("rect", width=size, height=size, fill="#fff"),
        _el("g", grid, fill="none", stroke="#bbb"),
        _el("g", aug, fill="var(--aug)", fill_opacity="0.85"),
        _el("g", src, fill="var(--src)", stroke="#fff", stroke_width=1),
        _el("path", d=f"M{mid - 7} {mid}h14M{mid} {mid - 7}v14", stroke="#222", stroke_width=2),
        _el("path", d=f"M12 {size - 14}h{_c(0.1 * scale)}", stroke="#222", stroke_width=2),  # 0.1 m scale bar
        _el("text", "0.1 m", x=12, y=size - 20, font_size=12),
        _el("text", "target", x=mid + 9, y=mid - 8, font_size=12),
    ]
    out = cov["outside_annulus"]
    desc = (
        f"Block start positions on the table, seen from above, around the target at the centre. The "
        f"spawn annulus from {r_min:.2f} to {r_max:.2f} m is split into {rings} rings and {sectors} "
        f"sectors ({cov['cells']} cells). {len(src_starts)} source starts (squares) cover "
        f"{cov['source']} cells; with the {len(aug_starts)} kept augmented starts (dots) "
        f"{cov['union']} cells hold a start. Outside the annulus: {out['source']} source, "
        f"{out['augmented']} augmented."
    )
    title = f"Coverage of block starts: {cov['source']} -> {cov['union']} of {cov['cells']} cells"
    return _svg("cov", size, size, title, desc, body)


def _bars_svg(metrics: dict) -> str:
    """The 2x2: success with its 95% interval, two data arms side by side within each budget."""
    arms, budgets, eff = metrics["arms"], metrics["budgets"], metrics["effects"]
    order = [b for b in BUDGET_ORDER if b in budgets] + sorted(set(budgets) - set(BUDGET_ORDER))
    w, h, x0, x1, top, bot = 380, 296, 54, 372, 22, 216
    (y, body), desc, group = _axes(x0, x1, top, bot), [], (x1 - x0) / len(order)
    for i, budget in enumerate(order):
        cx = x0 + group * (i + 0.5)
        for j, data in enumerate(DATA_COLOURS):
            rate, (lo, hi) = arms[f"{data}_{budget}"]["success"], arms[f"{data}_{budget}"]["ci95"]
            bx = cx + (j - 0.5) * 60
            bar_h = max(y(0) - y(rate), 1.5)  # a zero rate still shows a sliver of its colour
            whisker = f"M{_c(bx)} {_c(y(lo))}V{_c(y(hi))}" + "".join(
                f"M{_c(bx - 8)} {_c(y(v))}h16" for v in (lo, hi)
            )
            body += [
                _el("rect", x=bx - 24, y=y(0) - bar_h, width=48, height=bar_h, fill=DATA_VAR[data]),
                _el("path", d=whisker, stroke="#222", stroke_width=1.6, fill="none"),
                _el("text", f"{rate:.2f}", class_="vl", x=bx, y=y(hi) - 6, text_anchor="middle"),
            ]
            desc.append(
                f"{DATA_LABEL[data]} at the {budget} budget {rate:.2f} (95% interval {lo:.2f} to {hi:.2f})"
            )
        effect = eff.get(f"data_{budget}")
        lines = [("gl", f"{_e(budget)} budget"), ("gs", f"{budgets[budget]:,} steps each")]
        lines += [] if effect is None else [("gs", f"data: {_pts(effect)} points")]
        for k, (cls, text) in enumerate(lines):
            body.append(_el("text", text, class_=cls, x=cx, y=bot + 24 + 19 * k, text_anchor="middle"))
    body.append(_el("line", x1=x0, x2=x1, y1=bot, y2=bot, stroke="#444"))
    n = metrics["config"]["eval_episodes"]
    title = f"Success of the BC policy on {n} held-out PushT starts, by data and budget"
    return _svg("bars", w, h, title, "; ".join(desc) + ".", body)


def kept_embodiment(path: Path = EMBODIMENT) -> dict | None:
    """tools.embodiment's kept result (a full run, not a smoke one), or None where there is none."""
    try:
        result = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    ok = (
        isinstance(result, dict)
        and result.get("kind") == "embodiment"
        and " --smoke" not in result["command"]
    )
    return result if ok else None


def measured_embodiment(result: dict) -> str:
    """Objective 2's numbers as one caption sentence (HTML), read from tools.embodiment's result: each
    arm's success pooled over seeds, per robot, with its Wilson 95% interval."""
    p = result["pooled"]

    def rate(arm: str, robot: str) -> str:
        q = p[arm][robot]
        return f"<b>{q['rate']:.2f}</b> [{q['ci95'][0]:.2f}, {q['ci95'][1]:.2f}]"

    per_robot = "; ".join(
        f"{NAMES[robot]}: its own policy {rate(own, robot)}, shared {rate('shared', robot)}, shared with "
        f"the id {rate('shared_id', robot)}, that policy told the other robot's id "
        f"{rate('shared_id_swapped', robot)}"
        for robot, own in (("pusht", "pusht_only"), ("aloha", "aloha_only"))
    )
    n, seeds = p["shared"]["pusht"]["episodes"], len(result["rows"])
    return (
        f"Measured (<code>{_e(result['command'])}</code>, {seeds} seeds, {n} held-out starts per robot and "
        f"policy, success with 95% intervals): {per_robot}."
    )


def _strip(cross: dict) -> str:
    """Each robot's action, padded to the widest: real dimensions named, padding hatched."""
    pad, rows, said = cross["padded_action_dim"], [], []
    for e in cross["embodiments"]:
        names = [_e(n).replace("_", "_<wbr>") for n in e["action_names"][: e["act_dim"]]] + ["pad"] * pad
        name = NAMES.get(e["name"], _e(e["name"]))
        rows.append(
            f'<div class="who"><b>{name}</b> {e["act_dim"]} of {pad} real<small>{e["frames"]:,} frames, mask '
            f"density {e['mask_density']:.3f}</small></div>"
        )
        for d, kind in enumerate(["real"] * e["act_dim"] + ["pad"] * (pad - e["act_dim"])):
            rows.append(f'<div class="dim {kind}"><small>{d}</small>{names[d]}</div>')
        said.append(f"<code>{_e(cross['state_index_2_means'][e['name']])}</code> in {name}")
    real = (_sw("var(--real)"), "real action dimension (in the loss)")
    legend = _legend([real, (_sw("#dcdcdc"), "zero padding (mask 0: no loss, no gradient)")])
    return (
        '<figure class="wide" aria-labelledby="strip-t">\n<h2 id="strip-t">Cross-embodiment: one action '
        f"head of width {pad}, a mask over the padding</h2>\n{legend}\n"
        f'<div class="strip">{"".join(rows)}</div>\n'
        f"<figcaption>Largest gradient on PushT's padded dimensions under the masked loss: "
        f"<b>{cross['padded_dim_max_grad']:.1f}</b>. State index 2 is {' and '.join(said)}: a shared network "
        "carries structure across robots, not the meaning of a raw state number."
        + (f" {measured_embodiment(kept)}" if (kept := kept_embodiment()) else "")
        + "</figcaption>\n</figure>"
    )


def chapter_html(metrics: dict, cross: dict, src_starts, aug_starts, annulus, reference: str = "") -> str:
    """scale_data.html's text from the run's metrics.json and cross_embodiment.json dicts and the block
    starts (src_starts (S, 2), aug_starts (K, 2), metres); annulus = (r_min, r_max, rings, sectors);
    reference: a sentence placing this seed beside meta.yaml's five-seed reference (ch37.cli), or ""."""
    m = _as_written(metrics)
    rate = {k: a["success"] for k, a in m["arms"].items()}
    b, eff, cov, cfg = m["budgets"], m["effects"], m["coverage"], m["config"]
    n_eval, out = cfg["eval_episodes"], cov["outside_annulus"]
    run = f"seed {m['seed']}" + (", smoke" if m["smoke"] else "")
    frames = {"source": m["source_frames"], "augmented": m["source_frames"] + m["augmented_frames"]}
    src_sw = (_sw("var(--src)"), f"source starts ({len(src_starts)})")
    aug_sw = (_sw("var(--aug)", "sw dot"), f"kept augmented starts ({len(aug_starts)})")
    legend_cov = _legend([src_sw, aug_sw])
    legend_bars = _legend((_sw(DATA_VAR[d]), f"{DATA_LABEL[d]} ({frames[d]:,} frames)") for d in DATA_COLOURS)
    body = f"""\
<header>
<p class="kicker">Chapter 3.7 &middot; Datasets at Scale &middot; scale_data.py &middot; {run}</p>
<h1>See it work: {m["source_demos"]} demos grown to {m["source_demos"] + m["kept"]} by \
{GROWN_BY.get(m["aug_mode"], _e(m["aug_mode"]))}, measured</h1>
<p class="headline">At equal steps ({b["full"]:,} each), source only <b>{rate["source_full"]:.2f}</b> \
&rarr; source + augmented <b>{rate["augmented_full"]:.2f}</b> ({_pts(eff["data_full"])} points) on \
{n_eval} held-out PushT starts.</p>
{f"<p>One seed is one draw: {_e(reference)}.</p>" if reference else ""}
<p>At the short budget ({b["short"]:,} steps): {rate["source_short"]:.2f} &rarr; \
{rate["augmented_short"]:.2f} ({_pts(eff["data_short"])}). More steps alone: source \
{_pts(eff["compute_source"])}, source + augmented {_pts(eff["compute_augmented"])}. Coverage \
<b>{cov["source"]} &rarr; {cov["union"]} of {cov["cells"]}</b> cells. The data engine \
({_e(m["aug_mode"])}) kept <b>{m["kept"]}</b> of {m["attempts"]} attempts (yield {m["yield"]:.2f}) \
from {m["source_demos"]} source demos.</p>
{SMOKE if m["smoke"] else ""}</header>
<div class="row">
<figure class="square" aria-labelledby="cov-h">
<h2 id="cov-h">Where the block starts: {cov["source"]} &rarr; {cov["union"]} of {cov["cells"]} cells</h2>
{legend_cov}{_coverage_svg(src_starts, aug_starts, cov, annulus)}
<figcaption>Each start is the block's position when a demo begins; a cell counts once it holds one. \
Augmented alone: {cov["augmented"]} cells. Outside the annulus, kept but in no cell (a perturbed block \
may lie on a band a little wider than the annulus): source {out["source"]}, augmented \
{out["augmented"]}.</figcaption>
</figure>
<figure aria-labelledby="bars-h">
<h2 id="bars-h">Success on {n_eval} held-out starts, 95% intervals</h2>
{legend_bars}{_bars_svg(m)}
<figcaption>Within a budget both arms take the same gradient steps from the same initial weights and \
batch order: the data is the only difference. Intervals are Wilson 95% over {n_eval} episodes.</figcaption>
</figure>
</div>
{_strip(_as_written(cross))}"""
    kept = ", and objective 2's line from <code>results/embodiment.json</code>" if kept_embodiment() else ""
    note = (
        f"Run: {run}, device {_e(cfg.get('device'))}. Drawn from this run's <code>metrics.json</code> and "
        "<code>cross_embodiment.json</code>"
        + (", beside <code>meta.yaml</code>'s five-seed reference" if reference else "")
        + (kept or ("" if reference else " only"))
        + "; the page holds no date (metrics.json has none), so the same flags write the same bytes."
    )
    rates = f"source {rate['source_full']:.2f} -> source+aug {rate['augmented_full']:.2f}"
    return _doc(f"Datasets at Scale, {run}: {rates}", body, note, cfg)


def chapter(
    path: Path, metrics: dict, cross: dict, src_starts, aug_starts, annulus, reference: str = "", claim=None
) -> Path:
    """Write scale_data.html (see chapter_html), whole or not at all; returns its path."""
    html_text = chapter_html(metrics, cross, src_starts, aug_starts, annulus, reference)
    return write_atomic(Path(path), html_text, claim)


# --- scale_lab.html --------------------------------------------------------------------------------
def _curve(result: dict, curve: str) -> list[tuple[int, dict]]:
    """[(N, row)] of one curve in N order."""
    return sorted(((int(n), r) for n, r in result["curves"].get(curve, {}).items()), key=lambda t: t[0])


def _f3(x: float) -> str:
    return f"{x:.3f}"


def _ci(r: dict) -> str:
    return f"{_f3(r['success'])} [{_f3(r['ci95'][0])}, {_f3(r['ci95'][1])}]"


def _demos(d: float) -> str:  # a mean over seeds: whole demos as an integer, else one decimal
    return f"{d:.0f}" if d == round(d) else f"{d:.1f}"


def answer_bend(result: dict) -> str:
    """Where the fresh curve bends: the N where its rise per tripling of N grows the most."""
    rows = [(n, r["success"]) for n, r in _curve(result, "fresh")]
    if len(rows) < 3:
        return f"It takes at least three N to see a bend; this run measured {len(rows)}."
    slopes = [(s2 - s1) / math.log(n2 / n1, 3) for (n1, s1), (n2, s2) in zip(rows, rows[1:])]
    turns = [slopes[i] - slopes[i - 1] for i in range(1, len(slopes))]
    i = max(range(len(turns)), key=lambda k: (turns[k], -k))
    if turns[i] <= 0:
        measured = ", ".join(f"{_f3(s)} at {n}" for n, s in rows)
        return f"No upward bend within N = {rows[0][0]} to {rows[-1][0]}: fresh demos give {measured}."
    (na, sa), (nb, sb), (nc, sc), (nl, sl), (nz, sz) = rows[i], rows[i + 1], rows[i + 2], rows[-2], rows[-1]
    return (
        f"Fresh demos bend at N = <b>{nb}</b>: {slopes[i]:+.2f} per tripling of N before it ({_f3(sa)} at "
        f"{na} &rarr; {_f3(sb)} at {nb}), <b>{slopes[i + 1]:+.2f}</b> after it ({_f3(sc)} at {nc}). The "
        f"last step, {nl} &rarr; {nz}, still adds {slopes[-1]:+.2f} per tripling ({_f3(sl)} &rarr; "
        f"{_f3(sz)})."
    )


def matched_fresh(result: dict, success: float) -> float | None:
    """The fresh-demo count with this success, log-linear between measured fresh points (on a rising
    segment); None if no rising segment of the fresh curve holds it."""
    rows = [(n, r["success"]) for n, r in _curve(result, "fresh")]
    for (n1, f1), (n2, f2) in zip(rows, rows[1:]):
        if f2 > f1 and f1 <= success <= f2:
            return math.exp(math.log(n1) + (success - f1) / (f2 - f1) * math.log(n2 / n1))
    return None


def exchange_rows(result: dict) -> list[dict]:
    """Every generated point past the sources, read off the fresh curve: how many fresh demos it
    matches and what one generated demo is worth ((matched - sources) / generated)."""
    sources, out = result["config"]["sources"], []
    for curve in ("resolve", "replay"):
        for n, r in _curve(result, curve):
            if r["demos"] > sources:
                fresh = matched_fresh(result, r["success"])
                worth = None if fresh is None else (fresh - sources) / (r["demos"] - sources)
                out.append(dict(r, curve=curve, n=n, fresh=fresh, worth=worth))
    return out


def answer_exchange(result: dict) -> str:
    """The exchange rows as a table, under how they were read."""
    rows = "".join(
        f"<tr><td>{SHORT[r['curve']]}</td><td>{_demos(r['demos'])}</td><td>{_f3(r['success'])}</td>"
        + ("<td>-</td><td>off the rising fresh curve</td>" if r["worth"] is None else "")
        + ("" if r["worth"] is None else f"<td>{r['fresh']:.0f}</td><td><b>{r['worth']:.2f}</b></td>")
        + "</tr>"
        for r in exchange_rows(result)
    )
    return (
        f"Each generated point read off the fresh curve (log-linear between fresh points): the fresh "
        f"demos it matches, and what one generated demo is worth in fresh ones, (matched - "
        f"{result['config']['sources']}) / generated."
        '<div class="scroll"><table><thead><tr><th>engine</th><th>demos</th><th>success</th>'
        f"<th>&asymp; fresh</th><th>worth</th></tr></thead><tbody>{rows}</tbody></table></div>"
        if rows
        else "No generated point past the sources was measured."
    )


def answer_compute(result: dict) -> str:
    """Data or compute: the last step in N at the fixed budget against the same step at N's budget."""
    res, fix = _curve(result, "resolve"), _curve(result, "resolve_fixed")
    if len(res) < 2 or len(fix) < 2:
        return "It takes at least two N to compare."
    (na, ra), (nb, rb), fa, fb = res[-2], res[-1], fix[-2][1], fix[-1][1]
    seed = str(result["config"]["seeds"][0])
    fixed = result["fixed_steps"].get(seed, fa["steps"][0])
    d_fix, d_full = fb["success"] - fa["success"], rb["success"] - ra["success"]
    return (
        f"From {na} to {nb} re-solved demos at the fixed budget ({fixed:,} steps, seed {seed}): "
        f"{_f3(fa['success'])} &rarr; {_f3(fb['success'])} (<b>{d_fix:+.3f}</b>). The same data at "
        f"{result['config']['epochs']} epochs ({ra['steps'][0]:,} &rarr; {rb['steps'][0]:,} steps, seed "
        f"{seed}): {_f3(ra['success'])} &rarr; {_f3(rb['success'])} (<b>{d_full:+.3f}</b>). The first is "
        "what the extra data buys alone, the second what it buys with the steps to learn it."
    )


def answer_ceiling(result: dict) -> str:
    """The best point of any curve (ties: the earlier curve, then the smaller N) against the expert."""
    points = ((curve, n, r) for curve in LAB_STYLE for n, r in _curve(result, curve))
    curve, n, r = max(points, key=lambda t: (t[2]["success"], -list(LAB_STYLE).index(t[0]), -t[1]))
    e = result["expert"]
    return (
        f"Best point: {_e(LAB_STYLE[curve][2])} at N = {n}, {_ci(r)}. The expert on the same starts: "
        f"{_ci(e)}. Gap: <b>{e['success'] - r['success']:.3f}</b>."
    )


def _lab_svg(result: dict) -> str:
    """Success against demos (log x), one line per curve with its pooled band, the default point
    starred, the expert's success dashed."""
    ns = result["config"]["n"]
    w, h, x0, x1, top, bot = 560, 380, 58, 540, 30, 320
    lo_n, hi_n = math.log(min(ns) / 1.15), math.log(max(ns) * 1.15)

    def x(demos):
        return x0 + (math.log(demos) - lo_n) / (hi_n - lo_n) * (x1 - x0)

    y, body = _axes(x0, x1, top, bot)
    xticks = [_el("line", x1=x(n), x2=x(n), y1=bot, y2=bot + 5, stroke="#444") for n in ns]
    xticks += [_el("text", n, x=x(n), y=bot + 24) for n in ns]
    xticks.append(_el("text", "PushT demos trained on (log scale)", x=(x0 + x1) // 2, y=h - 4))
    body, desc = body + [_el("g", xticks, class_="tk", text_anchor="middle")], []
    for curve, (colour, ls, label) in LAB_STYLE.items():
        rows, hexc = [r for _, r in _curve(result, curve)], HEX[colour]
        if rows:
            band = [(x(r["demos"]), y(r["ci95"][1])) for r in rows]
            band += [(x(r["demos"]), y(r["ci95"][0])) for r in reversed(rows)]
            line = [(x(r["demos"]), y(r["success"])) for r in rows]
            body.append(_el("polygon", points=band, fill=hexc, fill_opacity="0.13"))
            body.append(_el("polyline", points=line, fill="none", stroke=hexc, stroke_width=2.5, **DASH[ls]))
            body += [_el("circle", cx=a, cy=b, r=3.5, fill=hexc) for a, b in line]
            at = ", ".join(f"{_f3(r['success'])} at {_demos(r['demos'])} demos" for r in rows)
            desc.append(f"{label}: {at}")
    e = result["expert"]["success"]
    body += [
        _el("line", x1=x0, x2=x1, y1=y(e), y2=y(e), stroke="#444", stroke_width=1.6, stroke_dasharray="6 4"),
        _el("text", f"expert {e:.2f}", x=x1, y=y(e) - 6, class_="tk", text_anchor="end"),
    ]
    point = result["curves"].get(LAB_DEFAULT[0], {}).get(LAB_DEFAULT[1])
    if point is not None:  # a five-pointed star, radii 10 and 4.2
        cx, cy, rr, th = x(point["demos"]), y(point["success"]), [10, 4.2] * 5, math.pi / 5
        star = [(cx + rr[k] * math.sin(k * th), cy - rr[k] * math.cos(k * th)) for k in range(10)]
        body.append(_el("polygon", points=star, fill="#111", stroke="#fff", stroke_width=1))
        desc.append(f"the chapter's default point, N = {LAB_DEFAULT[1]} re-solve: {_f3(point['success'])}")
    desc.append(f"the expert's own success: {e:.3f}")
    title = "Success of the BC policy against PushT demos, four curves, with pooled 95% bands"
    return _svg("lab", w, h, title, "; ".join(desc) + ".", body)


def _lab_table(result: dict) -> str:
    """Every point: one row per N, one column per curve (narrow enough for a phone)."""
    head = "".join(f"<th>{_sw(HEX[c])}{SHORT[k]}</th>" for k, (c, *_) in LAB_STYLE.items())
    rows = []
    for n in result["config"]["n"]:
        rows.append(f"<tr><th>{n}</th>")
        for r in (result["curves"].get(curve, {}).get(str(n)) for curve in LAB_STYLE):
            if r is None:
                rows.append("<td>-</td>")
                continue
            kept = "" if r["demos"] == n else f"<small>{_demos(r['demos'])} demos</small>"
            rows.append(f"<td><b>{_f3(r['success'])}</b><small>{_ci(r).split(' ', 1)[1]}</small>{kept}</td>")
        rows.append("</tr>")
    return (
        '<h2 id="pts-h">Every point: success, mean over seeds [pooled Wilson 95%]</h2>\n'
        '<div class="scroll"><table class="points" aria-labelledby="pts-h"><thead><tr><th>N</th>'
        f"{head}</tr></thead><tbody>{''.join(rows)}</tbody></table></div>"
    )


def lab_html(result: dict) -> str:
    """scale_lab.html's text, drawn from the scale_lab.json dict alone."""
    r = _as_written(result)
    cfg, gen = r["config"], []
    for mode in sorted(r.get("generation", {}), key=lambda k: (k != "resolve", k)):
        by_seed = r["generation"][mode].values()
        att, kept = sum(g["attempts"] for g in by_seed), sum(g["kept"] for g in by_seed)
        gen.append(f"{mode} kept <b>{kept:,}</b> of {att:,} attempts ({kept / att if att else 0:.3f})")
    legend = [(_sw(HEX[c]), _e(label)) for c, _, label in LAB_STYLE.values()]
    if LAB_DEFAULT[1] in r["curves"].get(LAB_DEFAULT[0], {}):  # starred only where it was measured
        legend.append((STAR, f"the chapter's default point (N = {LAB_DEFAULT[1]}, re-solve)"))
    legend.append((_sw(cls="sw dash"), "the expert's own success"))
    seeds = ("seeds " if len(cfg["seeds"]) > 1 else "seed ") + ", ".join(map(str, cfg["seeds"]))
    answers = (answer_bend(r), answer_exchange(r), answer_compute(r), answer_ceiling(r))
    body = f"""\
<header>
<p class="kicker">Chapter 3.7 &middot; Datasets at Scale &middot; the Scale Lab &middot; \
{seeds}{" &middot; smoke" if r.get("smoke") else ""}</p>
<h1>See it work: success against the number of demos</h1>
<p class="headline">The chapter's BC recipe at N = {", ".join(map(str, cfg["n"]))} PushT demos: fresh \
expert demos against 12 sources grown by the data engine, equal steps per N; the expert's own success \
is <b>{r["expert"]["success"]:.2f}</b>.</p>
<p>Data engine: {"; ".join(gen)}.</p>
{SMOKE if r.get("smoke") else ""}</header>
<div class="row">
<figure class="wide" aria-labelledby="lab-h">
<h2 id="lab-h">Success against demos, mean over seeds; band = Wilson 95% of \
{cfg["eval_episodes"] * len(cfg["seeds"]):,} pooled episodes</h2>
{_legend(legend)}{_lab_svg(r)}
<figcaption>Replay is plotted at the demos it kept. The fixed-budget curve trains every N for \
N = {cfg["fixed_n"]}'s steps; the others take {cfg["epochs"]} epochs of the re-solve set at each N.\
</figcaption>
</figure>
</div>
<section aria-labelledby="ans-h">
<h2 id="ans-h">The four answers, read off the curves</h2>
<ol>{"".join(f"<li><b>{q}</b> {a}</li>" for q, a in zip(QUESTIONS, answers))}</ol>
</section>
{_lab_table(r)}"""
    note = (
        f"Command: <code>{_e(r['command'])}</code>. Intervals: {_e(r.get('interval', ''))}. Drawn from "
        "<code>scale_lab.json</code> only (its wall-clock seconds left out), so the same flags write the "
        "same bytes, locally or on Ray."
    )
    return _doc(f"Scale Lab: success against demos (seeds {cfg['seeds']})", body, note, cfg)


def lab(path: Path, result: dict, claim=None) -> Path:
    """Write scale_lab.html (see lab_html), whole or not at all; returns its path."""
    return write_atomic(Path(path), lab_html(result), claim)
