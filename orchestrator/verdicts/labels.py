"""The labels of our ports' enumerations, for a run's columns.json (orchestrator/results.py
``columns``): what each integer value of a recorded output stands for.

One row per enumerated port of our roles, naming where its labels are stated — beside the
values the units compute with, from which the ports' descriptions are also written
(fmus/fmi/ports.py ``enumeration_text``): the aspects and each cab system's codes in the
registry of cab systems (fmus/signalling/cab_systems.py), the block signal's aspects in
fmus/signalling/block_rules.py, the coder's status, the ATO's modes and the ATP's
interventions in their cores. A port of another FMU has no labels here (a Boolean's false,
true are the results' own).
"""
from __future__ import annotations

from typing import Callable, Dict, Mapping, Optional, Tuple

from fmus import ato_controller, loco_receiver, wayside_coder
from fmus.ato_controller.atp import INTERVENTION_NAMES
from fmus.ato_controller.core import MODE_NAMES
from fmus.errors import FmuInputError
from fmus.signalling import cab_systems
from fmus.signalling.block_rules import SIGNAL_NAMES
from fmus.wayside_coder.core import STATUS_NAMES
from orchestrator.graph import Node, SystemGraph
from orchestrator.ports import base_of
from orchestrator.verdicts.verdict import system_object

ATO, RECEIVER, CODER = (ato_controller.MODEL_IDENTIFIER, loco_receiver.MODEL_IDENTIFIER,
                        wayside_coder.MODEL_IDENTIFIER)


def _parameter(node: Node, name: str, default: str) -> str:
    """A String parameter as the FMU reads it: the system's value, else its start value."""
    value = node.parameters.get(name)
    if value in (None, ""):
        variable = node.interface.variables.get(name)
        value = variable.start if variable is not None and variable.start not in (None, "") else default
    return str(value)


def _codes(node: Node) -> Mapping[int, str]:
    """The codes of the cab system the component's ``system`` names, from its code table (its
    ``codes_file``, else the bundled one), as a receiver of its ``train_category`` reads them."""
    cab = cab_systems.lookup(_parameter(node, "system", cab_systems.DEFAULT.name))
    system = system_object(cab, node.parameters)
    return cab.code_labels(system, _parameter(node, "train_category", "passenger"))


#: (model identifier, port) → the labels of its values for that component
ENUMERATIONS: Dict[Tuple[str, str], Callable[[Node], Mapping[int, str]]] = {
    (RECEIVER, "aspect"): lambda node: cab_systems.ASPECT_LABELS,
    (RECEIVER, "code"): _codes,
    (CODER, "code_tx"): _codes,
    (CODER, "signal"): lambda node: SIGNAL_NAMES,
    (CODER, "status"): lambda node: STATUS_NAMES,
    (ATO, "atp_aspect"): lambda node: cab_systems.ASPECT_LABELS,
    (ATO, "mode"): lambda node: MODE_NAMES,
    (ATO, "atp_intervention"): lambda node: INTERVENTION_NAMES,
}


def railway_labels(graph: SystemGraph) -> Dict[Tuple[str, str], Mapping[int, str]]:
    """(component, port) → value → label for every enumerated port of the graph's components
    (``RunOptions.labels``). A code table that does not load gives no labels: the component
    itself says what is wrong with it when the run starts."""
    found: Dict[Tuple[str, str], Mapping[int, str]] = {}
    for name, node in graph.nodes.items():
        ports = {base_of(variable) for variable in node.interface.variables}
        for (model, port), labels_of in ENUMERATIONS.items():
            if node.interface.model_identifier != model or port not in ports:
                continue
            labels: Optional[Mapping[int, str]]
            try:
                labels = labels_of(node)
            except (FmuInputError, OSError, ValueError, KeyError):
                labels = None
            if labels:
                found[(name, port)] = dict(labels)
    return found
