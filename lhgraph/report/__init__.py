"""What a person reads: text tables (``text``), the HTML report (``html``) and the 3-D
viewer (``viewer``); rendered from plain data, importing nothing from ``workflow``.
"""
