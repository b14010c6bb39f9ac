"""What is measured: a station's measurement model of either generation (``station``:
station-frame point -> angle, factory calibration, Jacobians, the inverse; ``lh1`` the
Lighthouse v1 rotors, ``lh2`` the Lighthouse v2 light planes), factory calibration files
(``calibration``), Bitcraze's conventions (``bitcraze``), the sensor board and its TOML
(``board``) and the built-in boards (``boards``).
"""
