"""kite_rto: real-time optimization of a crosswind power kite with Generalized Modifier Adaptation."""
__version__ = "0.1.0"
