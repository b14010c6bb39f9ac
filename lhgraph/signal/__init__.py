"""lhgraph.signal.pulses."""
