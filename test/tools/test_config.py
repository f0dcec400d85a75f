"""config/kite_rto.yaml matches the parameters the nodes declare."""
from pathlib import Path

from kite_rto.tools.config_yaml import render

ROOT = Path(__file__).resolve().parents[2]


def test_config_file_is_generated_from_the_declared_parameters():
    assert (ROOT / "config" / "kite_rto.yaml").read_text() == render(), \
        "regenerate: python -m kite_rto.tools.config_yaml > config/kite_rto.yaml"


def test_docs_parameter_table_is_generated_from_the_declared_parameters():
    from kite_rto.tools.config_yaml import TABLE_BEGIN, TABLE_END, render_markdown
    text = (ROOT / "docs" / "parameters.md").read_text()
    assert text.count(TABLE_BEGIN) == 1 and text.count(TABLE_END) == 1
    block = text[text.index(TABLE_BEGIN) + len(TABLE_BEGIN):text.index(TABLE_END)]
    assert block == "\n" + render_markdown(), \
        "regenerate: python -m kite_rto.tools.config_yaml --doc docs/parameters.md"


def test_parameter_table_lists_every_parameter_of_every_node():
    from kite_rto.tools.config_yaml import node_params, render_markdown
    rows = [line.split(" | ") for line in render_markdown().splitlines()[2:]]
    expected = [(node, f"`{s.name}`", "yes" if s.runtime else "no") for node, specs in node_params() for s in specs]
    assert [(r[0].lstrip("| "), r[1], r[4]) for r in rows] == expected
    assert {"k_psi", "rate_factor", "n_iter", "delta"} <= {s.name for _, specs in node_params() for s in specs
                                                           if s.runtime}
