"""lhgraph.estimation."""
