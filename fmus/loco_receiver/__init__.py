"""Locomotive receiver unit: ALSN receiver chain and decoder (core.py, filters.py) and its FMU
facade (facade.py)."""
MODEL_IDENTIFIER = "LocoReceiver"
