"""Rigid-body maths in GTSAM's conventions: SE(3)/SO(3) exp/log, ``T_a_b`` products,
interpolation (``transforms``) and the weighted Kabsch fit (``kabsch``).
"""
