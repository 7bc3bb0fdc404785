"""Behavioural conformance of an FMU to a role: `railcosim conform --role ROLE TARGET`.

A role's test vectors (data/<role>.json, its arrays in data/<role>.npz) are written by
``python -m orchestrator.conformance.generate`` from our model cores and the documented bounds;
the runner (runner.py) feeds a target their inputs step by step as a host would and the judges
(judges.py) hold the outputs to the bounds (docs/contracts.md, "Behavioural conformance").
"""

#: the roles, as the units' folders under fmus/ name them
ROLES = ("loco_receiver", "wayside_coder", "rail_line", "traction", "ato_controller")
