"""Behavioural conformance of an FMU to a role: `railcosim conform --role ROLE TARGET`.

The data flows one way: a role's test vectors (vectors.py reads data/<role>.json and its
arrays in data/<role>.npz, written by ``python -m orchestrator.conformance.generate`` from our
model cores and the documented bounds) → the target (target.py opens an FMU and its ports) →
the runner (runner.py steps it as a host would, its ports through port_io.py, an ATO's closed
loop through plant.py) → the judges (judges.py hold the trace to the bounds) → the report
(report.py, a table or JSON); roles.py finds the roles' shipped interface manifests
(docs/contracts.md).
"""

#: the roles, as the units' folders under fmus/ name them
ROLES = ("loco_receiver", "wayside_coder", "rail_line", "traction", "ato_controller")
