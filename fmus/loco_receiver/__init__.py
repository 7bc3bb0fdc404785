"""Locomotive receiver unit: ALSN receiver chain (core.py, filters.py), its decoder and display
(alsn_decoder.py), the other systems' receivers and its FMU facade (facade.py)."""
MODEL_IDENTIFIER = "LocoReceiver"
