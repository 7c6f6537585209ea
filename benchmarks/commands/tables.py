"""How the commands print their statistics."""
from __future__ import annotations

from benchmarks.metrics import STAT_COLUMNS


def summary_line(name: str, stats: dict) -> str:
    return (f"{name}: mean {stats['mean_deg']:.4f} deg, std {stats['std_deg']:.4f} deg, "
            f"max {stats['max_deg']:.4f} deg, final {stats['final_deg']:.4f} deg")


def format_table(stats: dict, first_column: str = "estimator", columns=STAT_COLUMNS) -> str:
    """A fixed-width text table of ``{row name: statistics}``."""
    width = max(len(first_column), *(len(str(name)) for name in stats))
    lines = [f"{first_column:<{width}}  " + "  ".join(f"{c:>15}" for c in columns)]
    for name, row in stats.items():
        lines.append(f"{str(name):<{width}}  " + "  ".join(f"{row[c]:>15.6f}" for c in columns))
    lines += [f"note: {name}: {row['note']}" for name, row in stats.items() if row.get("note")]
    return "\n".join(lines)
