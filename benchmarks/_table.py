"""The markdown table every benchmark prints (``benchmarks/run.py`` collects its rows)."""


def print_table(rows) -> None:
    """Print ``| benchmark | value | target | met |`` and one line per row (a tuple of 4 values)."""
    print("| benchmark | value | target | met |")
    print("|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(str(v) for v in r) + " |")
