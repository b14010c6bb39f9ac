"""The capture board over USB serial: framing and CRC (``protocol``), the serial link
(``link``), the capture procedure (``download``) and progress display (``progress``).
"""
