"""Traction unit: longitudinal train dynamics (core.py) and its FMU facade (facade.py)."""
MODEL_IDENTIFIER = "Traction"
