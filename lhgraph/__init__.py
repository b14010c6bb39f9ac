"""lhgraph: factor-graph calibration of Lighthouse v1 base stations.

Modules: ``model`` (measurement model), ``transforms`` (SE(3) helpers), ``board``,
``angles``, ``stations``, ``calibration``, ``trajectory`` (contract files), ``metrics``,
``simulate``, ``baseline`` (the paper's method), ``graph`` (the factor-graph solver),
``cli``.
"""

__version__ = "0.1.0"
