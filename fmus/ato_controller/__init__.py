"""ATO controller unit: ATP supervision (atp.py), offline running-time planning (planner.py),
online driving strategies (driving.py), their composition (core.py) and the FMU facade."""
MODEL_IDENTIFIER = "AtoController"
