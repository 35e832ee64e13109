"""A small report document written both as HTML and as Markdown.

Later jobs (identification, cross-check, criticism, population) add their own sections to
the same :class:`Report`, so the demo grows without a new report format per issue.
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from workbench.fileutil import atomic_write_text

__all__ = ["Figure", "Report", "Section", "Table"]


@dataclass(frozen=True)
class Table:
    """A table: column headers and rows of already formatted cells."""

    columns: list[str]
    rows: list[list[str]]
    caption: str = ""

    def to_html(self) -> str:
        """Render as an HTML table."""
        head = "".join(f"<th>{html.escape(c)}</th>" for c in self.columns)
        body = "".join(
            "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>"
            for row in self.rows
        )
        cap = f"<caption>{html.escape(self.caption)}</caption>" if self.caption else ""
        return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"

    def to_markdown(self) -> str:
        """Render as a GitHub-flavoured Markdown table."""

        def cell(c: object) -> str:
            return str(c).replace("|", "\\|").replace("\n", " ")

        lines = [
            "| " + " | ".join(cell(c) for c in self.columns) + " |",
            "|" + "|".join("---" for _ in self.columns) + "|",
        ]
        lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in self.rows]
        if self.caption:
            lines = [f"*{self.caption}*", "", *lines]
        return "\n".join(lines)


@dataclass(frozen=True)
class Figure:
    """A figure already saved as a file, referenced relative to the report folder."""

    path: str
    caption: str


@dataclass
class Section:
    """A titled section: paragraphs, tables, figures and bullet lists, in order."""

    title: str
    blocks: list[str | Table | Figure | list[str]] = field(default_factory=list)

    def paragraph(self, text: str) -> Section:
        """Append a paragraph of plain text."""
        self.blocks.append(text)
        return self

    def table(self, table: Table) -> Section:
        """Append a table."""
        self.blocks.append(table)
        return self

    def figure(self, path: str, caption: str) -> Section:
        """Append a figure (``path`` relative to the report folder)."""
        self.blocks.append(Figure(path, caption))
        return self

    def bullets(self, items: list[str]) -> Section:
        """Append a bullet list (skipped when empty)."""
        if items:
            self.blocks.append(list(items))
        return self

    def to_html(self) -> str:
        """Render the section as HTML."""
        out = [f"<section><h2>{html.escape(self.title)}</h2>"]
        for block in self.blocks:
            if isinstance(block, Table):
                out.append(block.to_html())
            elif isinstance(block, Figure):
                out.append(
                    f'<figure><img src="{html.escape(block.path)}" alt="'
                    f'{html.escape(block.caption)}"><figcaption>{html.escape(block.caption)}'
                    "</figcaption></figure>"
                )
            elif isinstance(block, list):
                out.append("<ul>" + "".join(f"<li>{html.escape(b)}</li>" for b in block) + "</ul>")
            else:
                out.append(f"<p>{html.escape(block)}</p>")
        out.append("</section>")
        return "\n".join(out)

    def to_markdown(self) -> str:
        """Render the section as Markdown."""
        out = [f"## {self.title}", ""]
        for block in self.blocks:
            if isinstance(block, Table):
                out += [block.to_markdown(), ""]
            elif isinstance(block, Figure):
                out += [f"![{block.caption}]({block.path})", "", f"*{block.caption}*", ""]
            elif isinstance(block, list):
                out += [f"- {b}" for b in block] + [""]
            else:
                out += [block, ""]
        return "\n".join(out)


_CSS = """
body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:0.9em}
th,td{border:1px solid #bbb;padding:0.3em 0.6em;text-align:left;vertical-align:top}
th{background:#eee} caption{caption-side:bottom;font-style:italic;padding-top:0.3em}
figure{margin:1em 0} img{max-width:100%} figcaption{font-style:italic;font-size:0.9em}
section{border-top:1px solid #ccc;margin-top:2em}
"""


@dataclass
class Report:
    """A report: title, introduction and sections, written as ``index.html`` and ``report.md``."""

    title: str
    intro: str = ""
    sections: list[Section] = field(default_factory=list)

    def add(self, section: Section) -> Section:
        """Append a section and return it."""
        self.sections.append(section)
        return section

    def to_html(self) -> str:
        """Render the whole report as one HTML page."""
        stamp = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
        body = "\n".join(s.to_html() for s in self.sections)
        intro = f"<p>{html.escape(self.intro)}</p>" if self.intro else ""
        return (
            "<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(self.title)}</title><style>{_CSS}</style></head><body>"
            f"<h1>{html.escape(self.title)}</h1><p><small>generated {stamp}</small></p>"
            f"{intro}\n{body}\n</body></html>\n"
        )

    def to_markdown(self) -> str:
        """Render the whole report as Markdown."""
        parts = [f"# {self.title}", ""]
        if self.intro:
            parts += [self.intro, ""]
        parts += [s.to_markdown() for s in self.sections]
        return "\n".join(parts)

    def write(self, out_dir: str | Path) -> Path:
        """Write ``index.html`` and ``report.md`` into ``out_dir``; return the HTML path."""
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out_dir / "report.md", self.to_markdown())
        return atomic_write_text(out_dir / "index.html", self.to_html())
