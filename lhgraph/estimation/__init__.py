"""Everything that estimates: pure residuals and Jacobians (``residuals``), the problem
arranged by board state (``problem``), az/el pairing (``reconstruct``), initialisers
(``init``), the factor graph (``graph``), the paper's method (``baseline``), the shared result
(``result``), gravity alignment (``gravity``) and errors against a truth (``metrics``).
"""
