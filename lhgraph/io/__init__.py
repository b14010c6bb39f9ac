"""lhgraph.io."""
