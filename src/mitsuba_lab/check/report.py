"""The output of ``mitsuba-lab check``: the table, the verdicts with their evidence, CSV, HTML."""
from __future__ import annotations

import html

from ..reporting import dict_rows, fmt, html_page, html_table, write_csv as write_table, write_text

COLUMNS = ("scene", "film", "strategy", "status", "finite_fraction", "negative_pixels", "max_value",
           "fireflies", "mean", "ref_mean", "z", "camera_rays_per_pixel",
           "extension_rays_per_pixel", "shadow_rays_per_pixel", "other_rays_per_pixel", "time_s", "z_twin", "note", "evidence")


def _fmt(value, digits=4) -> str:
    return fmt(value, digits, missing="-")


def format_table(rows: list[dict]) -> str:
    head = (f"{'scene':26s} {'strategy':18s} {'status':24s} {'finite':>7s} {'neg':>5s} {'max':>9s} "
            f"{'ffly':>5s} {'mean':>9s} {'z':>7s} {'cam/px':>7s} {'ext/px':>7s} {'shd/px':>7s} {'oth/px':>7s}")
    lines = [head]
    for r in rows:
        lines.append(
            f"{r['scene'][:26]:26s} {r['strategy'][:18]:18s} {r['status'][:24]:24s} "
            f"{_fmt(r.get('finite_fraction')):>7s} {_fmt(r.get('negative_pixels')):>5s} "
            f"{_fmt(r.get('max_value')):>9s} {_fmt(r.get('fireflies')):>5s} {_fmt(r.get('mean')):>9s} "
            f"{_fmt(r.get('z'), 3):>7s} {_fmt(r.get('camera_rays_per_pixel'), 3):>7s} "
            f"{_fmt(r.get('extension_rays_per_pixel'), 3):>7s} {_fmt(r.get('shadow_rays_per_pixel'), 3):>7s} "
            f"{_fmt(r.get('other_rays_per_pixel'), 3):>7s}"
            + (f"  {r['note']}" if r.get("note") and not verdict_kind(r) else
               "  (see the verdicts below)" if verdict_kind(r) else ""))
    return "\n".join(lines)


def verdict_kind(row: dict) -> str:
    """'FAIL', 'WARNING', 'REFERENCE OFF' or '' (nothing to explain)."""
    status = row.get("status", "")
    if status.startswith("FAIL"):
        return "FAIL"
    if status.startswith("WARN"):
        return "WARNING"
    return "REFERENCE OFF" if status == "reference: OFF" else ""


def format_verdicts(rows: list[dict]) -> str:
    """Every failure, warning and wrong reference with its verdict and evidence, after the table."""
    lines = []
    for row in rows:
        kind = verdict_kind(row)
        if not kind or row.get("status") == "same":
            continue
        lines.append(f"{kind}  {row['scene']}  {row['strategy']}: {row.get('note') or row['status']}")
        lines.extend(f"    {line}" for line in row.get("evidence") or [] if line != row.get("note"))
    return "\n".join(["", "Verdicts (warnings do not change the exit status):", *lines]) if lines else ""


def write_csv(path: str, rows: list[dict]) -> None:
    flat = [{**row, "evidence": " | ".join(row["evidence"]) if isinstance(row.get("evidence"), list)
             else row.get("evidence", "")} for row in rows]
    write_table(path, COLUMNS, dict_rows(flat, COLUMNS))


#: Row colours of the HTML table by status.
ROW_STYLE = ("tr.fail td { background: #fcc; } tr.warn td, tr.off td { background: #ffe9a8; } "
             "tr.skipped td, tr.same td { color: #777; }")


def write_html(path: str, rows: list[dict], warnings: dict[str, list[str]], settings: str, doc: str) -> None:
    """The page: settings, ``doc`` (check's module doc, less its title), warnings, verdicts, table."""
    parts = ["<h1>mitsuba-lab check</h1>", f"<p>{html.escape(settings)}</p>",
             f"<pre>{html.escape(doc.split(chr(10) * 2, 1)[1])}</pre>"]
    if any(warnings.values()):
        parts.append("<h2>Warnings</h2><ul>")
        for scene, notes in warnings.items():
            parts.extend(f"<li>{html.escape(scene)}: {html.escape(n)}</li>" for n in notes)
        parts.append("</ul>")
    verdicts = format_verdicts(rows)
    if verdicts:
        parts.append(f"<h2>Verdicts</h2><pre>{html.escape(verdicts.strip())}</pre>")
    classes = []
    for row in rows:
        kind = {"FAIL": "fail", "WARNING": "warn", "REFERENCE OFF": "off"}.get(verdict_kind(row))
        classes.append(kind or (row.get("status", "").split(":")[0].split() or [""])[0])
    csv_rows = [{**row, "evidence": " | ".join(row.get("evidence") or [])} for row in rows]
    parts.append(html_table(COLUMNS, [[_fmt(row.get(c)) for c in COLUMNS] for row in csv_rows], classes))
    write_text(path, html_page("mitsuba-lab check", "\n".join(parts), ROW_STYLE))
