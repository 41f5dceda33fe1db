"""Plain-text tables, counts and lists for the command line: left-aligned text, right-aligned numbers, "1 shard",
"a, b and c"."""
from __future__ import annotations

from typing import Sequence

__all__ = ["format_table", "counted", "listed"]


def format_table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    cells = [[str(h) for h in headers]] + [[f"{v:.2f}" if isinstance(v, float) else str(v) for v in r] for r in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    numeric = [all(isinstance(r[i], (int, float)) for r in rows) if rows else False for i in range(len(headers))]
    lines = []
    for row in cells:
        lines.append("  ".join(c.rjust(w) if numeric[i] else c.ljust(w) for i, (c, w) in enumerate(zip(row, widths)))
                     .rstrip())
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """`n` and its noun, singular for one: counted(1, "shard") is "1 shard", counted(4, "shard") "4 shards"."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def listed(words, conjunction: str = "and") -> str:
    """Words as a phrase: "a", "a and b", "a, b and c" (or "or" as the `conjunction`)."""
    words = list(words)
    return words[0] if len(words) == 1 else f"{', '.join(words[:-1])} {conjunction} {words[-1]}"
