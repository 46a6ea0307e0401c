"""report.html: one self-contained page (pictures inline, plotly.js inline, no network) that a
clinician reads at a glance: warnings, the custom cushion's numbers beside the stock cushion's, the
assembled mask's figures, the 3-D view, the pictures, all numbers of fit.json with units, and where
the result came from.

Every number taken from fit.json is shown in an element with data-key (its path in fit.json) and
data-scale (the factor applied for display, e.g. 100 for a percentage), and every one from mask.json
with data-mask-key, so tests can compare."""

import base64
import html
from dataclasses import dataclass

from ..evaluation.fit import CUSHIONS


# key suffix -> (unit, display factor, decimals)
UNITS = (
    ("_fraction", "%", 100.0, 1), ("_mm", "mm", 1.0, 2), ("_kpa", "kPa", 1.0, 2), ("_mmhg", "mmHg", 1.0, 1),
    ("_cmh2o", "cmH₂O", 1.0, 1), ("_force_n", "N", 1.0, 1), ("_l_min", "L/min", 1.0, 2), ("_cv", "", 1.0, 3),
    ("_deg", "°", 1.0, 1), ("_mm2", "mm²", 1.0, 0), ("_ml", "ml", 1.0, 1),
)
MASK_ROWS = (  # (path in mask.json, label, unit, decimals)
    ("port.standard", "hose connector", "", 0),
    ("port.tip_mm", "connector's tip (scan frame)", "mm", 1),
    ("port.axis", "connector's axis, out of the face (scan frame)", "", 3),
    ("vents.count", "exhaust vent holes", "", 0),
    ("vents.diameter_mm", "vent hole diameter", "mm", 2),
    ("vents.flow_l_min.4_cmh2o", "vent flow at 4 cmH₂O", "L/min", 1),
    ("vents.flow_l_min.10_cmh2o", "vent flow at 10 cmH₂O", "L/min", 1),
    ("vents.flow_l_min.20_cmh2o", "vent flow at 20 cmH₂O", "L/min", 1),
    ("valve.opening_mm", "anti-asphyxia valve opening (oronasal masks)", "mm", 1),
    ("dead_space_ml", "dead space (air between the face and the connector)", "ml", 1),
    ("dead_space_limit_ml", "dead space limit", "ml", 0),
    ("ring_clearance_mm", "frame ring over the nose tip", "mm", 1),
    ("assembly.interference_mm3", "cushion and frame overlap (interference)", "mm³", 3),
    ("assembly.airway_closed", "airway closed from the connector to the face but at the vents and valve", "", 0),
)
HEADLINE = (  # (key under fit["custom"|"stock"|"generic"], label)
    ("contact_fraction", "rim in contact with the skin"),
    ("window_fraction", "rim within the safe pressure window"),
    ("pressure_mean_kpa", "mean contact pressure"),
    ("pressure_cv", "pressure variation along the rim (coefficient of variation)"),
    ("pressure_max_kpa", "peak contact pressure"),
    ("pressure_max_mmhg", "peak contact pressure"),
    ("leak_l_min", "leak at the set CPAP pressure"),
    ("headgear_force_n", "headgear force (custom: set for the awake and sleeping face; stock: as a clinic sets it)"),
    ("seal_force_n", "least headgear force that seals"),
    ("gap_before_load_median_mm", "rim-to-skin gap before load, median (custom: with its pre-load)"),
    ("rim_covered_fraction", "rim over scanned skin (the numbers above are over this part)"),
)


@dataclass(frozen=True)
class Picture:
    """A picture of the report: file name, heading, caption (how to read it) and PNG bytes."""

    name: str
    heading: str
    caption: str
    png: bytes


@dataclass(frozen=True)
class Page:
    """Everything report.html shows. fit: the fit.json record; traceability: [(label, text)]; viewer: an HTML fragment."""

    title: str
    fit: dict
    notices: tuple
    pictures: tuple
    traceability: tuple
    viewer: str
    mask: dict  # the mask.json record


def unit_of(key: str) -> tuple[str, float, int]:
    """(unit, display factor, decimals) of a fit.json key, from its suffix."""
    for suffix, unit, factor, decimals in UNITS:
        if key.endswith(suffix):
            return unit, factor, decimals
    return "", 1.0, 3


def value_cell(path: str, value, tag: str = "td", key: str = "key", decimals: int | None = None) -> str:
    """A cell showing a record's value; numbers carry data-`key` (fit.json's: data-key) and data-scale,
    shown to `decimals` (None: by the path's unit), a list's numbers to `decimals` too."""
    if isinstance(value, list) and decimals is not None:
        value = [round(v, decimals) for v in value]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        text = {True: "yes", False: "no", None: "—"}.get(value, value) if isinstance(value, (bool, type(None))) else value
        text = ", ".join(map(str, text)) if isinstance(text, list) else str(text)
        return f"<{tag}>{html.escape(text)}</{tag}>"
    unit, factor, by_unit = unit_of(path)
    shown = f"{value * factor:.{by_unit if decimals is None else decimals}f}" if isinstance(value, float) else str(value)
    return f'<{tag} class="num" data-{key}="{path}" data-scale="{factor:g}">{shown}</{tag}>'


def lookup(fit: dict, path: str):
    """The value at a dotted path of a nested dict, or None."""
    node = fit
    for part in path.split("."):
        if isinstance(node, list) and part.isdigit() and int(part) < len(node):
            node = node[int(part)]
        elif isinstance(node, dict) and part in node:
            node = node[part]
        else:
            return None
    return node


def cushions_in(fit: dict) -> list[str]:
    """The cushions the record evaluates (`CUSHIONS` present), in order."""
    return [c for c in CUSHIONS if isinstance(fit.get(c), dict)]


def cushion_label(fit: dict, name: str) -> str:
    """A cushion's column heading: the stock cushion with its size and how it was chosen."""
    stock = fit.get("stock_fitting", {})
    if name == "stock_gauge":
        return f"stock cushion, size {stock.get('gauge_size', '?')} (the gauge's pick)"
    if name != "stock":
        return f"{name} cushion"
    tried = len(stock.get("sizes_best_first", {})) + len(stock.get("not_seated", []))
    how = "best size by fit" if tried > 1 else "size as evaluated"
    return f"stock cushion, size {stock.get('size', '?')} ({how}; the gauge picks {stock.get('gauge_size', '?')})"


def headline_table(fit: dict) -> str:
    """The custom cushion beside the cushions it is compared with: the evaluation's numbers (those present)."""
    cushions, body = cushions_in(fit), []
    for key, label in HEADLINE:
        paths = [f"{c}.{key}" for c in cushions]
        if lookup(fit, paths[0]) is None:
            continue
        cells = "".join(value_cell(p, lookup(fit, p)) for p in paths)
        body.append(f"<tr><th>{html.escape(label)}</th>{cells}<td>{html.escape(unit_of(key)[0])}</td></tr>")
    head = "".join(f"<th>{html.escape(cushion_label(fit, c))}</th>" for c in cushions)
    return f'<table class="headline"><thead><tr><th></th>{head}<th>unit</th></tr></thead><tbody>{"".join(body)}</tbody></table>'


def settings_line(fit: dict) -> str:
    """The custom cushion's headgear force and the CPAP pressure; the stock sizes that found no seat,
    or why no stock cushion is compared where one was asked for."""
    force = value_cell("headgear_force_n", fit["headgear_force_n"], "b")
    line = f'<p class="force">Headgear force: {force} N at a CPAP pressure of {value_cell("cpap_cmh2o", fit["cpap_cmh2o"], "b")} cmH₂O.</p>'
    unseated = fit.get("stock_fitting", {}).get("not_seated")
    if unseated:
        line += f'<p class="stock-note">Stock sizes tried that find no seat on this face: {html.escape(", ".join(unseated))}.</p>'
    if "stock_not_fitted" in fit:
        line += f'<p class="stock-note">No stock cushion compared: {html.escape(fit["stock_not_fitted"])}.</p>'
    return line


def flatten(record: dict, prefix: str = "") -> list[tuple[str, object]]:
    """[(dotted path, leaf value)] of a nested dict, in order; a list of dicts by index."""
    out = []
    for key, value in record.items():
        path = f"{prefix}{key}"
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            value = {str(i): v for i, v in enumerate(value)}
        out += flatten(value, path + ".") if isinstance(value, dict) else [(path, value)]
    return out


STATE_COLUMNS = (("leak_l_min", "leak"), ("window_fraction", "in window"), ("pressure_max_kpa", "peak"))


def _peak_where(fit: dict | None) -> str:
    """Where a cushion's peak pressure is in a state, that the CPAP load lifted it off the face, or
    a dash where it was not evaluated."""
    if fit is None:
        return "—"
    return "lifted off: the CPAP load beats the straps" if fit["lifted_off"] else str(fit["pressure_max_region"])


def _state_cell(fit: dict, path: str, key: str) -> str:
    """A state's `key` of the cushion at `path`; no leak figure where the CPAP load lifts it off (the mask is off)."""
    if key == "leak_l_min" and lookup(fit, f"{path}.lifted_off"):
        return "<td>mask off</td>"
    return value_cell(f"{path}.{key}", lookup(fit, f"{path}.{key}"))


def states_table(fit: dict) -> str:
    """Each state of the sleeping face (fit.json's `states`): every cushion's leak, window fraction,
    peak pressure and where; empty when the record has no states."""
    states = fit.get("states") or []
    cushions = [c for c in cushions_in(fit) if any(c in row for row in states)]
    if not cushions:
        return ""
    head = "".join(f"<th>{c}: {label} ({unit_of(key)[0]})</th>" for c in cushions for key, label in STATE_COLUMNS)
    body = []
    for i, row in enumerate(states):
        cells = "".join(_state_cell(fit, f"states.{i}.{c}", key) for c in cushions for key, _ in STATE_COLUMNS)
        cells += "".join(f"<td>{html.escape(_peak_where(row.get(c)))}</td>" for c in cushions)
        note = f"<br><small>not evaluated: {html.escape(row['error'])}</small>" if "error" in row else ""
        body.append(f"<tr><th>{html.escape(row['name'])}{note}</th>{cells}</tr>")
    head += "".join(f"<th>{c}: peak where</th>" for c in cushions)
    return ("<h2>Asleep: the same cushions in each state of the sleeping face</h2>\n<p>Lying on the back with the jaw "
            "dropped, the mask pushed sideways or rolled by a pillow, and the CPAP range's ends, each cushion at the headgear "
            "force set for it awake. A leak of more than a few L/min, or a peak over the window's top, is where a cushion "
            "fails the sleeping face.</p>\n"
            f'<table class="states"><thead><tr><th>state</th>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>')


def mask_table(mask: dict) -> str:
    """The assembled mask's figures from mask.json: connector, vents, valve, dead space, the airway."""
    rows = "".join(f"<tr><th>{html.escape(label)}</th>{value_cell(path, lookup(mask, path), key='mask-key', decimals=decimals)}"
                   f"<td>{html.escape(unit)}</td></tr>" for path, label, unit, decimals in MASK_ROWS)
    return ("<h2>The assembled mask</h2>\n<p>The cushion fits into a rigid frame (frame.stl; both in place in assembly.3mf) that "
            "takes the CPAP hose and the headgear; mask.json holds these figures and the rest.</p>\n"
            f'<table class="mask"><tbody>{rows}</tbody></table>')


def numbers_table(fit: dict) -> str:
    """Every value of fit.json, by its path, with its unit."""
    rows = "".join(f"<tr><th><code>{html.escape(p)}</code></th>{value_cell(p, v)}<td>{html.escape(unit_of(p)[0])}</td></tr>"
                   for p, v in flatten(fit))
    return f'<table class="numbers"><thead><tr><th>fit.json</th><th>value</th><th>unit</th></tr></thead><tbody>{rows}</tbody></table>'


def notices_block(notices: tuple) -> str:
    if not notices:
        return '<div class="notice ok">No warnings: the scan covers the seal and the template follows it.</div>'
    rescan = any(n.level == "rescan" for n in notices)
    head = '<p class="rescan">Rescan advised.</p>' if rescan else ""
    items = "".join(f'<li class="{n.level}">{html.escape(n.text)}</li>' for n in notices)
    return f'<div class="notice {"bad" if rescan else "warn"}"><h2>Warnings</h2>{head}<ul>{items}</ul></div>'


def picture_block(p: Picture) -> str:
    data = base64.b64encode(p.png).decode()
    return (f'<figure id="{html.escape(p.name)}"><h3>{html.escape(p.heading)}</h3>'
            f'<img src="data:image/png;base64,{data}" alt="{html.escape(p.heading)}">'
            f"<figcaption>{html.escape(p.caption)} <span class=\"file\">({html.escape(p.name)})</span></figcaption></figure>")


STYLE = """
body{font:16px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,"DejaVu Sans",sans-serif;color:#1b1b1b;margin:0;background:#f4f5f7}
main{max-width:1320px;margin:0 auto;padding:16px 24px;background:#fff}
h1{font-size:1.7em;margin:.2em 0}h2{font-size:1.3em;margin:1.2em 0 .4em;border-bottom:2px solid #d0d4da}h3{margin:.2em 0}
.sub{color:#555;margin:0 0 1em}
table{border-collapse:collapse;margin:.4em 0}th,td{padding:4px 10px;border-bottom:1px solid #e1e4e8;text-align:left;vertical-align:top}
td.num{text-align:right;font-variant-numeric:tabular-nums}
table.headline{font-size:1.05em}table.headline th[scope],table.headline tbody th{font-weight:normal}
table.numbers{font-size:.9em}
.notice{padding:10px 16px;border-radius:6px;margin:1em 0}.notice h2{border:0;margin:0}
.ok{background:#e5f5e0;border:1px solid #a1d99b}.warn{background:#fff4e0;border:1px solid #fdae6b}.bad{background:#fde0dd;border:1px solid #f768a1}
.rescan{font-weight:bold;font-size:1.1em;color:#a50f15;margin:.3em 0}
li.rescan{font-weight:normal;font-size:1em;color:inherit}
.force{font-size:1.1em}
figure{margin:1.2em 0}figure img{max-width:100%;height:auto;border:1px solid #e1e4e8}figcaption{color:#333;max-width:70em}
.file{color:#777;font-size:.9em}
#viewer-box{border:1px solid #e1e4e8}
details summary{cursor:pointer;font-weight:bold;margin:.5em 0}
"""


def report_html(page: Page) -> bytes:
    """The page as UTF-8 bytes (same page, same bytes)."""
    trace = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in page.traceability)
    pictures = "".join(picture_block(p) for p in page.pictures)
    body = f"""<main>
<h1>{html.escape(page.title)}</h1>
<p class="sub">cpapfit report. All lengths in millimetres; pressures in kPa (1 kPa = 7.5 mmHg = 10.2 cmH₂O).</p>
{notices_block(page.notices)}
<h2>At a glance: {html.escape(" vs ".join(cushions_in(page.fit)))} cushion</h2>
{settings_line(page.fit)}
{headline_table(page.fit)}
{states_table(page.fit)}
{mask_table(page.mask)}
<h2>3-D view</h2>
<p>Drag to turn, scroll to zoom, hover over a rim for its value. The buttons show the custom cushion or the other cushion's rim.</p>
<div id="viewer-box">{page.viewer}</div>
<h2>Pictures</h2>
{pictures}
<h2>All numbers</h2>
<details><summary>Every value in fit.json, with units</summary>{numbers_table(page.fit)}</details>
<h2>Traceability</h2>
<table class="trace">{trace}</table>
</main>"""
    doc = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width, initial-scale=1">
<title>{html.escape(page.title)}</title><style>{STYLE}</style></head>
<body>{body}</body></html>
"""
    return doc.encode("utf-8")
