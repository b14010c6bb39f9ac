"""The named choices of the command line and the configuration files, in one numpy-free
module: the CLI builds its parsers from these without importing the code behind them
(start-up of every command), and the modules that act on a choice import it from here."""

METHODS = ("graph", "paper")
"""Calibration methods (``--method``, config ``method``/``methods``)."""
WORLDS = ("reference", "gravity")
"""World frames of a solution (``--world``, config ``world``)."""
FORMATS = ("lhcap", "raw", "libsurvive")
"""Recording kinds ``lhgraph decode`` reads (``--format``)."""
PERIODS = ("fit", "nominal")
"""How the decoder gets each rotor's period (``--period``)."""
SYNCS = ("measured", "fitted")
"""Which sync edge times the decoder uses (``--sync``)."""
RENDERERS = ("auto", "open3d", "matplotlib")
"""How ``lhgraph view`` draws (``--renderer``)."""
EXPORT_UP = ("auto", "imu", "ootx", "none")
"""Where ``lhgraph export cfclient`` takes up from (``--up``)."""
EXPORT_FRAMES = ("auto", "receiver-start", "reference-station", "world")
"""Whose origin / x axis ``lhgraph export cfclient`` uses (``--origin``, ``--x``)."""
EXPORT_IMU_SAMPLES = ("auto", "still", "all")
"""Which IMU samples give up for ``lhgraph export cfclient`` (``--imu-samples``)."""
