"""Everything the estimation knows of an inertial measurement unit, in one place.

- :mod:`.inertial`: the IMU stream sampled at the graph's board states (rates, specific
  forces, their noise), the twist factors' model and the first gravity;
- :mod:`.calibration`: the IMU's calibration (gyro scale, time offset, frame) found from a
  light-only solution;
- :mod:`.bridge`: the initialiser's bridge over stretches no station sees, by the gyro;
- :mod:`.twist_terms`: the twist factors' residuals and Jacobians, vectorised;
- :mod:`.combined`: GTSAM's preintegrated combined IMU factors;
- :mod:`.families`: both as factor families of the batch graph
  (:mod:`lhgraph.estimation.graph.families`).

The stream's file format is :mod:`lhgraph.io.imu`; the simulated IMU is
:mod:`lhgraph.sim.imu`.
"""
