"""lhgraph.model.lh1."""
