"""A study row's name in the report's tables, and a cell as "mean ± standard deviation"."""
from __future__ import annotations

import json
import math

__all__ = ["label", "pm"]


def pm(r: dict, col: str, fmt: str = ".2f") -> str:
    """A study cell's ``col`` as "mean ± standard deviation" ("-" where it is missing)."""
    v = r.get(col)
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    sd = r.get(f"{col}_sd", math.nan)
    return format(v, fmt) + (f" ± {format(sd, fmt)}" if not math.isnan(sd) else "")


def label(row: dict) -> str:
    """A row's (or cell's) name in the tables; a row held at a frame budget says it."""
    from .budget_rows import budget_of, held_label
    held = budget_of(row) is not None
    if row["method"] == "foveated":
        config = json.loads(row["config"])
        opts = config.get("options", {})
        # The options set besides the preset tell two rows of one preset apart, and so does
        # a row rendered at the lens centre whatever the eye does.
        rest = "".join(f", {k} {v}" for k, v in sorted(opts.items())
                       if k not in ("preset", "frame_ms"))
        fixed = ", fixed foveation" if config.get("eye_tracking") is False else ""
        name = f"{opts.get('preset', 'auto')} {row['spp']:.0f} spp{rest}{fixed}"
        return held_label(row, name) if held else name
    return held_label(row, "") if held else f"{row['method']} {row['spp']:.0f} spp"
