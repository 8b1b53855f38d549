"""Plain aligned text tables for terminal output, and generated references kept in the docs."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any


def format_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A plain aligned text table; floats are shown with 6 significant digits."""

    def cell(value: Any) -> str:
        return f"{value:.6g}" if isinstance(value, float) else str(value)

    text = [[cell(v) for v in row] for row in rows]
    widths = [max(len(h), *(len(r[i]) for r in text)) if text else len(h)
              for i, h in enumerate(headers)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(headers, widths, strict=True))]
    lines.append("  ".join("-" * w for w in widths))
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in text]
    return "\n".join(lines)


def with_section(text: str, markers: tuple[str, str], body: str) -> str:
    """``text`` (a page of the docs) with ``body`` between its two marker lines, in place of
    what was there: a generated reference kept in its page."""
    start, end = markers
    head, _, rest = text.partition(start + "\n")
    _, _, tail = rest.partition(end)
    return f"{head}{start}\n{body}{end}{tail}"
