"""The report's HTML page: one file, figures inlined as base64 PNG, no network, no scripts.

:class:`Page` collects sections (headings, paragraphs, figures, tables, lists) and
:meth:`Page.render` returns the document. Every text is HTML-escaped.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from dataclasses import dataclass, field

__all__ = ["Page"]

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 0;
       color: #1d1d1f; background: #fafafa; line-height: 1.45; }
main { max-width: 1120px; margin: 0 auto; padding: 1.5rem 2rem 3rem; background: #fff; }
h1 { font-size: 1.6rem; margin-bottom: 0.2rem; }
h2 { font-size: 1.25rem; border-bottom: 2px solid #e4e4e7; padding-bottom: 0.2rem;
     margin-top: 2.2rem; }
p.meta { color: #555; margin-top: 0; }
nav ol { columns: 2; }
figure { margin: 1rem 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #e4e4e7; }
figcaption { font-size: 0.9rem; color: #444; }
table { border-collapse: collapse; font-size: 0.88rem; margin: 0.8rem 0; width: 100%; }
th, td { border: 1px solid #d4d4d8; padding: 0.25rem 0.5rem; text-align: left;
         vertical-align: top; }
th { background: #f4f4f5; }
td.num { font-family: ui-monospace, Menlo, Consolas, monospace; text-align: right;
         white-space: nowrap; }
.note { background: #fff8e1; border-left: 4px solid #f5a623; padding: 0.4rem 0.8rem; }
.warn li { margin: 0.2rem 0; }
.ok { color: #2e7d32; }
td.status-pass, p.status-pass { background: #e8f5e9; color: #1b5e20; font-weight: 600; }
td.status-check, p.status-check { background: #fff8e1; color: #8a5a00; font-weight: 600; }
td.status-fail, p.status-fail { background: #ffebee; color: #b71c1c; font-weight: 600; }
p.verdict { font-size: 1.15rem; padding: 0.5rem 0.8rem; }
details summary { cursor: pointer; color: #333; }
"""


@dataclass
class _Section:
    anchor: str
    title: str
    parts: list[str] = field(default_factory=list)


class Page:
    """An HTML report under construction.

    Parameters
    ----------
    title : str
    meta : str
        A line under the title (tool, version, date, run folder).
    """

    def __init__(self, title: str, meta: str):
        self.title = title
        self.meta = meta
        self._sections: list[_Section] = []
        self.n_images = 0

    def section(self, anchor: str, title: str) -> None:
        """Start a new section (listed in the table of contents)."""
        self._sections.append(_Section(anchor, title))

    def _add(self, text: str) -> None:
        if not self._sections:
            self.section("top", self.title)
        self._sections[-1].parts.append(text)

    def paragraph(self, text: str) -> None:
        """A paragraph of plain text."""
        self._add(f"<p>{html.escape(text)}</p>")

    def note(self, text: str) -> None:
        """A highlighted note (e.g. a section skipped)."""
        self._add(f'<p class="note">{html.escape(text)}</p>')

    def figure(self, png: bytes, caption: str, alt: str) -> None:
        """An inlined PNG figure with its caption."""
        data = base64.b64encode(png).decode("ascii")
        self.n_images += 1
        self._add(
            f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(alt)}">'
            f"<figcaption>{html.escape(caption)}</figcaption></figure>"
        )

    def table(
        self,
        header: Sequence[str],
        rows: Sequence[Sequence[str]],
        numeric: Sequence[int] = (),
        status: int | None = None,
        collapsed: str | None = None,
    ) -> None:
        """A table.

        Parameters
        ----------
        header : sequence of str
        rows : sequence of sequence of str
        numeric : sequence of int
            Columns right-aligned in a monospace font.
        status : int, optional
            A column of ``pass``, ``check`` or ``fail``, coloured by its value.
        collapsed : str, optional
            Fold the table under this summary line (``<details>``, opened by a click).
        """
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = []
        for row in rows:
            cells = "".join(self._cell(i, c, numeric, status) for i, c in enumerate(row))
            body.append(f"<tr>{cells}</tr>")
        table = f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"
        if collapsed is not None:
            table = f"<details><summary>{html.escape(collapsed)}</summary>{table}</details>"
        self._add(table)

    @staticmethod
    def _cell(i: int, text: str, numeric: Sequence[int], status: int | None) -> str:
        if i == status:
            return f'<td class="status-{html.escape(text)}">{html.escape(text)}</td>'
        if i in numeric:
            return f'<td class="num">{html.escape(text)}</td>'
        return f"<td>{html.escape(text)}</td>"

    def status_line(self, status: str, text: str) -> None:
        """A prominent line coloured by ``status`` (``pass``, ``check`` or ``fail``)."""
        self._add(f'<p class="verdict status-{html.escape(status)}">{html.escape(text)}</p>')

    def items(self, items: Sequence[str], css: str = "") -> None:
        """A bulleted list."""
        cls = f' class="{css}"' if css else ""
        lis = "".join(f"<li>{html.escape(t)}</li>" for t in items)
        self._add(f"<ul{cls}>{lis}</ul>")

    def render(self) -> str:
        """The whole document."""
        toc = "".join(
            f'<li><a href="#{s.anchor}">{html.escape(s.title)}</a></li>' for s in self._sections
        )
        body = "".join(
            f'<section id="{s.anchor}"><h2>{html.escape(s.title)}</h2>{"".join(s.parts)}</section>'
            for s in self._sections
        )
        return (
            "<!DOCTYPE html>\n"
            '<html lang="en"><head><meta charset="utf-8">'
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head>"
            f"<body><main><h1>{html.escape(self.title)}</h1>"
            f'<p class="meta">{html.escape(self.meta)}</p>'
            f"<nav><ol>{toc}</ol></nav>{body}</main></body></html>\n"
        )
