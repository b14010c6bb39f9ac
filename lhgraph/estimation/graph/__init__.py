"""lhgraph.estimation.graph."""
