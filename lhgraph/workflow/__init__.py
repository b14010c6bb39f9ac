"""lhgraph.workflow."""
