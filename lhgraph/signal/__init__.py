"""From photodiode edges to angles: the ``.lhcap`` format (``capture``), light pulses
(``pulses``), sync flashes (``sync``), the decoder (``decode``, ``decode_report``), OOTX frames
(``ootx``), libsurvive recordings (``libsurvive``) and the dispatcher by file kind
(``formats``).
"""
