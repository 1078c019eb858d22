"""The look every HTML report of tagloc shares: one stylesheet, tables, embedded figures, a
verdict banner, a page.

``tagloc eval run``, ``tagloc eval bag``, ``tagloc eval bags`` and ``tagloc localize`` write
self-contained pages (figures as base64 PNG, no external file) with these helpers, so they read
alike.
"""

from __future__ import annotations

import base64
import html
import math
from collections.abc import Sequence

__all__ = ["CSS", "cell", "figure", "page", "table", "verdict"]

CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:0.6em 0}td,th{border:1px solid #ccc;padding:3px 8px;
text-align:right}th{background:#f2f2f2}td:first-child{text-align:left}.pass{background:#d9f2d9}
.fail{background:#f7d4d4}.unknown{background:#eee}img{max-width:100%}
.verdict{padding:0.6em 1em;margin:1em 0;font-size:1.15em;border-radius:4px}"""


def cell(value: object, digits: int = 4) -> str:
    """A table cell's text: ``n/a`` for None and non-finite floats, ``digits`` significant."""
    if value is None:
        return "n/a"
    if isinstance(value, float):
        return "n/a" if not math.isfinite(value) else f"{value:.{digits}g}"
    return html.escape(str(value))


def table(
    header: Sequence[str], rows: Sequence[Sequence[object]], classes: Sequence[str] | None = None
) -> str:
    """An HTML table (``classes``: one CSS class per row, e.g. ``pass``/``fail``)."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = []
    for i, row in enumerate(rows):
        cls = f' class="{classes[i]}"' if classes else ""
        body.append(f"<tr{cls}>" + "".join(f"<td>{cell(v)}</td>" for v in row) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def figure(png: bytes, alt: str) -> str:
    """A PNG embedded in the page."""
    data = base64.b64encode(png).decode("ascii")
    return f'<p><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}"></p>'


def verdict(passed: bool | None, text: str) -> str:
    """A banner: green (passed), red (failed) or grey (cannot tell), with ``text``."""
    cls = {True: "pass", False: "fail", None: "unknown"}[passed]
    word = {True: "PASS", False: "FAIL", None: "NO VERDICT"}[passed]
    return f'<div class="verdict {cls}"><b>{word}</b>: {html.escape(text)}</div>'


def page(title: str, parts: Sequence[str]) -> str:
    """The whole self-contained page (``title`` as text, ``parts`` as HTML)."""
    t = html.escape(title)
    return (
        f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{t}</title>"
        f"<style>{CSS}</style></head><body><h1>{t}</h1>{''.join(parts)}</body></html>\n"
    )
