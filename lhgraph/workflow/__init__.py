"""What a lab runs: method dispatch (``solve``), the solve configuration
(``solve_config``), input checks and loading (``inputs``), run directories (``rundir``),
studies (``study``) and the moving window (``window``).
"""
