"""Rail line unit: track circuits as component networks (network.py, track_circuit.py), the
plant with trains, coil EMF, interference and track relays (core.py), and its FMU facade."""
MODEL_IDENTIFIER = "RailLine"
