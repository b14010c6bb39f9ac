"""Simulated captures with known truth: configuration (``config``), station layouts
(``layout``), board motion (``motion``), the angle simulator (``simulate``) and raw captures
(``capture_sim``).
"""
