"""DCP 1.0 (Distributed Co-Simulation Protocol, Modelica Association) over UDP_IPv4.

What to import for what (docs/hil.md describes the protocol subset):

* Building and parsing PDUs — ``orchestrator.dcp.pdu``: one frozen dataclass per PDU
  (``StcRegister``, ``Stc`` for the header-only STC requests, ``StcRun``, ``StcDoStep``,
  ``CfgTimeRes``, ``CfgSteps``, ``CfgInput``, ``CfgOutput``, ``CfgNetworkInformation``,
  ``CfgParameter``, ``CfgScope``, ``Basic`` for CFG_clear/INF_state/INF_error, ``RspAck``,
  ``RspNack``, ``RspStateAck``, ``RspErrorAck``, ``NtfStateChanged``, ``DatInputOutput``), each
  with ``.encode() -> bytes``; ``decode(datagram) -> Pdu`` raises ``PduError`` (its
  ``error_code`` and readable header) for a malformed one. ``PayloadCodec([(DataType, count),
  ...])`` encodes/decodes DAT_input_output payloads and CFG_parameter configurations;
  ``next_seq`` steps a uint16 sequence id.
* Ids: ``PduType``, ``State``, ``ErrorCode``, ``OpMode``, ``DataType``, ``TransportProtocol``,
  ``Scope`` (IntEnums with the standard's numbers) in ``orchestrator.dcp.pdu``.
* The slave state machine: ``orchestrator.dcp.states`` (``allowed(state, type_id)``,
  ``enters(state, type_id)``, ``COMPLETES``, ``RUN_STATES``).
* Slave descriptions: ``orchestrator.dcp.dcpx`` — ``read_dcpx(path) -> SlaveDescription``
  (validated against the DCP schema; a defect is one UserError), ``write_dcpx(desc, path)``,
  ``description_from_fmu(interface, host, port)`` (the description our slave serves for an FMU;
  ``DcpVariable.fmi_names`` maps each DCP variable to its FMI variables, arrays row-major).
* The slave: ``orchestrator.dcp.slave`` (``railcosim dcp-slave``).
"""
