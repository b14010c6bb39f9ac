"""lhgraph: factor-graph calibration of Lighthouse base stations.

Subpackages by concern, from the bottom layer up (docs/architecture.md): ``geometry``,
``model``, ``io``, ``signal``, ``device``, ``estimation``, ``sim``, ``importers``, ``report``,
``workflow``; ``config`` (option declarations and TOML loading), ``errors`` (the exception
hierarchy) and ``cli`` (the command line, a thin layer over the rest).
"""

__version__ = "0.1.0"
