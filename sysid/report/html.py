"""HTML report pages: the one page template, tables, figures and the provenance section.

Every HTML report of the project (the main job's ``report/index.html``, a diagnosis' ``index.html``) is built
from these pieces, so the pages share one look (tables never wider than the page, images scaled to it) and one
escaping rule: text that comes from data (names, messages, file paths) goes through :func:`esc`; the helpers
take cells and bodies as HTML, so a caller can put markup (a link, bold text) in a cell on purpose.

Pages are written atomically (:func:`write_page`): a browser or a test never sees half a page. Figures are
referenced by relative paths, so a report folder opens from the file system without a server.
"""

from __future__ import annotations

import html
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

__all__ = ["REPORT_CSS", "esc", "table", "figure", "image", "provenance_section", "page", "write_page"]

# Tables never wider than the page (they scroll or wrap inside themselves); images scale down to the page.
REPORT_CSS = (
    "table{border-collapse:collapse;font-size:12px;margin:.5em 0;display:block;max-width:100%;overflow-x:auto}"
    "td,th{border:1px solid #bbb;padding:3px 6px;vertical-align:top;overflow-wrap:anywhere}"
    "th{background:#eee;text-align:left}code{font-size:11px;overflow-wrap:anywhere}"
    "ul.files{margin:0;padding-left:1.2em}img{max-width:100%}"
)


def esc(text: Any) -> str:
    """``text`` (any value, via ``str``) safe to place in HTML text or a quoted attribute."""
    return html.escape(str(text))


def _attr(name: str, value: str | None) -> str:
    return f" {name}='{esc(value)}'" if value else ""


def table(
    header: Sequence[str],
    rows: Iterable[Sequence[Any]],
    cls: str | None = None,
    row_classes: Sequence[str | None] | None = None,
) -> str:
    """A ``<table>`` with one header row; ``header`` and the cells of ``rows`` are HTML (escape data with
    :func:`esc` first). ``row_classes`` gives each body row a class (e.g. a stage's status)."""
    head = "<tr>" + "".join(f"<th>{h}</th>" for h in header) + "</tr>"
    body = []
    for i, row in enumerate(rows):
        rc = row_classes[i] if row_classes is not None else None
        body.append(f"<tr{_attr('class', rc)}>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>")
    return f"<table{_attr('class', cls)}>{head}{''.join(body)}</table>"


def image(src: str, alt: str = "", style: str | None = None) -> str:
    """An ``<img>`` of the figure at relative path ``src``."""
    return f"<img src='{esc(src)}'{_attr('alt', alt)}{_attr('style', style)}>"


def figure(src: str, caption: str) -> str:
    """A captioned figure (``caption`` is plain text; it is also the image's alt text)."""
    return f"<figure>{image(src, caption)}<figcaption>{esc(caption)}</figcaption></figure>"


def provenance_section(prov: dict[str, Any]) -> str:
    """The provenance record of :func:`sysid.report.provenance.collect` as ``<section id="provenance">``: version,
    commit, command, date, machine and every data file with its size and sha256."""
    rows = [
        ("version", f"{prov['package']} {prov['version']}"),
        ("git commit", prov["commit"]),
        ("command", prov["command"]),
        ("date (UTC)", prov["date_utc"]),
        ("machine", prov["machine"]),
    ]
    cells = "".join(f"<tr><th>{esc(k)}</th><td><code>{esc(v)}</code></td></tr>" for k, v in rows)
    if prov["data"]:
        files = "".join(
            f"<li><code>{esc(d['file'])}</code> — "
            + (
                f"{d['bytes']} bytes, sha256 <code>{d['sha256']}</code>"
                if d["sha256"]
                else "not a file (built in memory)"
            )
            + "</li>"
            for d in prov["data"]
        )
        cells += f"<tr><th>data</th><td><ul class='files'>{files}</ul></td></tr>"
    else:
        cells += "<tr><th>data</th><td>none read from files (generated in this run)</td></tr>"
    return f"<section id='provenance'><h2>Provenance</h2><table class='provenance'>{cells}</table></section>"


def page(title: str, body: str | Iterable[str], css: str = "", provenance: dict[str, Any] | None = None) -> str:
    """A whole HTML document: ``title`` (plain text), ``body`` (HTML, or parts joined by newlines), the shared
    :data:`REPORT_CSS` after the page's own ``css``, and the provenance section at the end when given."""
    parts = [body] if isinstance(body, str) else list(body)
    if provenance is not None:
        parts.append(provenance_section(provenance))
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>{esc(title)}</title>"
        f"<style>{css}{REPORT_CSS}</style></head><body>\n" + "\n".join(parts) + "\n</body></html>"
    )


def write_page(
    path: str | Path, title: str, body: str | Iterable[str], css: str = "", provenance: dict[str, Any] | None = None
) -> Path:
    """Write :func:`page` to ``path`` atomically; returns the path."""
    from sysid.data.safeio import atomic_write_text

    return atomic_write_text(path, page(title, body, css=css, provenance=provenance))
