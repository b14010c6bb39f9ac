"""lhgraph.importers."""
