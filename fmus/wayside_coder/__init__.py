"""Wayside coder unit: automatic-block aspect logic and ALSN code transmitters (core.py) and
its FMU facade (facade.py)."""
MODEL_IDENTIFIER = "WaysideCoder"
