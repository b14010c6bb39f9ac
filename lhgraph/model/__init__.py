"""What is measured: the Lighthouse v1 station model (``lh1``: station-frame point -> sweep
angle, factory calibration, Jacobians), factory calibration files (``calibration``), the sensor
board and its TOML (``board``) and the built-in boards (``boards``).
"""
