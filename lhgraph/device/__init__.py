"""lhgraph.device."""
