"""lhgraph.estimation.init."""
