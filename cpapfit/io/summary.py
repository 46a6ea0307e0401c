"""The summary of a batch, one row per scan: `summary.csv` and `batch_report.html` (one
self-contained page, no script, nothing fetched), the same table in both, units in the headers."""

import csv
import html
import io

from .. import __version__

STATUSES = ("designed", "unchanged", "failed")


def _number(value, digits: int) -> str:
    return "" if value is None else f"{value:.{digits}f}"


# (header, cell of a row): rows are `jobs.ScanResult`s
COLUMNS = (
    ("scan", lambda r: r.name),
    ("status", lambda r: r.status),
    ("time (s)", lambda r: _number(r.seconds, 1)),
    ("leak (L/min)", lambda r: _number(r.leak_l_min, 2)),
    ("window fraction (0-1)", lambda r: _number(r.window_fraction, 3)),
    ("warnings", lambda r: "; ".join(r.warnings)),
    ("error", lambda r: r.error),
)


def counts(rows) -> str:
    """"N scans: a designed, b unchanged, c failed"."""
    return f"{len(rows)} scans: " + ", ".join(f"{sum(r.status == s for r in rows)} {s}" for s in STATUSES)


def summary_csv(rows) -> bytes:
    """The table as CSV (UTF-8, header line first); an absent value is an empty cell."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([header for header, _ in COLUMNS])
    writer.writerows([[cell(r) for _, cell in COLUMNS] for r in rows])
    return buf.getvalue().encode()


STYLE = (
    "body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}"
    "th,td{border:1px solid #bbb;padding:.3em .6em;text-align:left;vertical-align:top}"
    "th{background:#eee}tr.failed td{background:#fde8e8}"
)


def summary_html(rows, mask: str) -> bytes:
    """The table as one self-contained HTML page; failed rows tinted."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h, _ in COLUMNS)
    body = "".join(
        f'<tr class="{html.escape(r.status)}">' + "".join(f"<td>{html.escape(cell(r))}</td>" for _, cell in COLUMNS) + "</tr>\n"
        for r in rows
    )
    return (
        f'<!doctype html>\n<html lang="en"><head><meta charset="utf-8"><title>cpapfit batch</title>'
        f"<style>{STYLE}</style></head><body>\n<h1>cpapfit batch</h1>\n"
        f"<p>{html.escape(counts(rows))}. Mask: {html.escape(mask)}; cpapfit {__version__}. Outputs of each scan in "
        "the folder of its name beside this page. An empty cell: the value is not in that scan's fit.json.</p>\n"
        f"<table><thead><tr>{head}</tr></thead><tbody>\n{body}</tbody></table>\n</body></html>\n"
    ).encode()
