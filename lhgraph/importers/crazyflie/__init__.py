"""Importer for the Crazyflie's uSD-card event log (Lighthouse deck, LH1) -> lhgraph contract
files.

:mod:`~lhgraph.importers.crazyflie.usdlog` reads and writes the log format,
:mod:`~lhgraph.importers.crazyflie.sweeps` turns its ``lhAngle`` events into angles (the
repeated pairs dropped), :mod:`~lhgraph.importers.crazyflie.clock` measures the log's clock
against the deck's, :mod:`~lhgraph.importers.crazyflie.mocap` puts the Qualisys recording
on the written clock and :mod:`~lhgraph.importers.crazyflie.convert` writes the
files (``lhgraph import crazyflie``; cfclient's system configuration is read by
:mod:`lhgraph.io.cfclient`). See docs/crazyflie.md.
"""

from lhgraph.importers.crazyflie.convert import CrazyflieImport, import_crazyflie
from lhgraph.importers.crazyflie.usdlog import (
    EventType,
    UsdLog,
    encode_usd_log,
    read_usd_log,
    write_usd_log,
)

__all__ = ["CrazyflieImport", "EventType", "UsdLog", "encode_usd_log", "import_crazyflie",
           "read_usd_log", "write_usd_log"]
