"""lhgraph.geometry."""
