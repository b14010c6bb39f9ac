"""Importer for the hive ROS1 recordings (Borges et al., IROS 2018) -> lhgraph contract files.

:mod:`~lhgraph.importers.hive.bag` reads a bag, :mod:`~lhgraph.importers.hive.conventions`
maps hive's axes and OOTX terms to ours (verified by
:mod:`~lhgraph.importers.hive.mapping_check`), :mod:`~lhgraph.importers.hive.convert` writes
the contract files (``lhgraph import hive``) and :mod:`~lhgraph.importers.hive.mocap`
aligns an estimated path with the recording's OptiTrack ground truth. See docs/hive.md.
"""

from lhgraph.importers.hive.bag import HiveBag, read_hive_bag
from lhgraph.importers.hive.convert import HiveImport, import_hive
from lhgraph.importers.hive.mocap import MocapAlignment, align_to_mocap

__all__ = ["HiveBag", "HiveImport", "MocapAlignment", "align_to_mocap", "import_hive",
           "read_hive_bag"]
