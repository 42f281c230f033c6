"""The HTML pages of the reports: Jinja2 templates shipped with the package, autoescaped.

Every report (``replay --report``, ``diagnose --report``, ``fleet-report``) is one
``index.html`` rendered from ``templates/base.html``: a title, a summary block of key
numbers, then sections of paragraphs, tables and figures. The Python side passes plain
text (never markup) and :class:`Table` / :class:`Figure` values; the template escapes
everything, so a joint named ``<elbow>`` or a reason with ``&`` reads as written.
"""

from __future__ import annotations

import datetime as dt
import functools
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jinja2

from genbacklash_core import __version__

__all__ = ["DASH", "Figure", "Section", "Table", "render", "write_page"]

DASH = "\u2013"  # an en dash: "no value" in a table cell, and date ranges


@dataclass(frozen=True)
class Table:
    """A table: header cells and rows of already formatted cells (text, escaped on output).

    Columns from ``numeric_from`` on are right-aligned (numbers), unless ``align`` gives
    each column's alignment: ``"l"`` (text) or ``"r"`` (numbers), e.g. ``"llrr"``.
    """

    head: Sequence[str]
    rows: Sequence[Sequence[str]]
    caption: str = ""
    numeric_from: int = 1
    align: str = ""

    @property
    def numeric(self) -> list[bool]:
        """Per column: right-aligned (a number)?"""
        if self.align:
            return [a == "r" for a in self.align.ljust(len(self.head), "l")]
        return [k >= self.numeric_from for k in range(len(self.head))]


@dataclass(frozen=True)
class Figure:
    """A PNG beside the page, with its caption (also its alt text)."""

    src: str
    caption: str


@dataclass(frozen=True)
class Section:
    """A titled part of a page: paragraphs, then bullet items, tables, a code block, figures."""

    title: str
    paragraphs: Sequence[str] = ()
    items: Sequence[str] = ()
    tables: Sequence[Table] = ()
    code: str = ""
    figures: Sequence[Figure] = ()
    subsections: Sequence[Section] = field(default_factory=tuple)


@functools.cache
def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.PackageLoader("genbacklash_ros.reports", "templates"),
        autoescape=jinja2.select_autoescape(["html"]),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )


def render(template: str, **context: Any) -> str:
    """Render ``templates/<template>`` with ``context`` (plus ``version`` and ``written``)."""
    written = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    context.setdefault("version", __version__)
    context.setdefault("written", written)
    return _environment().get_template(template).render(**context)


def write_page(
    path: str | Path,
    *,
    title: str,
    subtitle: str = "",
    summary: Sequence[tuple[str, str]] = (),
    alerts: Sequence[str] = (),
    sections: Sequence[Section] = (),
    template: str = "base.html",
    **extra: Any,
) -> Path:
    """Write one report page (see the module notes); returns ``path``."""
    page = render(
        template,
        title=title,
        subtitle=subtitle,
        summary=list(summary),
        alerts=list(alerts),
        sections=list(sections),
        **extra,
    )
    target = Path(path)
    target.write_text(page, encoding="utf-8")
    return target
