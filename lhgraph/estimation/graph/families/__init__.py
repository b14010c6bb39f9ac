"""The batch graph's factor families, one module each, behind one interface
(:mod:`.base`): :mod:`.bearing` (the sweeps' bearing factors and sweep-offset priors),
:mod:`.corrections` (the board's diode biases and sensor offsets), :mod:`.motion` (the
motion prior); the IMU's two are in :mod:`lhgraph.estimation.imu.families`.
:func:`lhgraph.estimation.graph.factors.factor_families` registers them."""
