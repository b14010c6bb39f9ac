"""lhgraph.sim."""
