"""lhgraph.report.text."""
