"""config/kite_rto.yaml matches the parameters the nodes declare."""
from pathlib import Path

from kite_rto.tools.config_yaml import render

ROOT = Path(__file__).resolve().parents[1]


def test_config_file_is_generated_from_the_declared_parameters():
    assert (ROOT / "config" / "kite_rto.yaml").read_text() == render(), \
        "regenerate: python -m kite_rto.tools.config_yaml > config/kite_rto.yaml"
