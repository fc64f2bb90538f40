"""Result tables as plain markdown (no extra dependency)."""

from __future__ import annotations

import math

import pandas as pd


def to_markdown(df: pd.DataFrame, fmt: str = "{:.4g}") -> str:
    """A plain markdown table (no extra dependency); NaN shows as a dash."""
    def cell(v) -> str:
        if isinstance(v, float):
            return "-" if math.isnan(v) else fmt.format(v)
        return str(v)

    def label(c) -> str:
        return " ".join(str(x) for x in c) if isinstance(c, tuple) else str(c)

    names = [label(n) for n in (df.index.names if any(df.index.names) else [""])]
    head = [" / ".join(names)] + [label(c) for c in df.columns]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for idx, row in df.iterrows():
        lines.append("| " + " | ".join([label(idx)] + [cell(v) for v in row]) + " |")
    return "\n".join(lines) + "\n"
