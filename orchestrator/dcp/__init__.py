"""DCP 1.0 (Distributed Co-Simulation Protocol, Modelica Association) over UDP_IPv4: both roles.

What to import for what (docs/hil.md describes the protocol as railcosim speaks it):

* PDUs — ``orchestrator.dcp.pdu``: the ids of the standard (``PduType``, ``State``,
  ``ErrorCode``, ``OpMode``, ``DataType``, ``TransportProtocol``, ``Scope``), every PDU's wire
  layout as one row of ``LAYOUTS``, ``Pdu(type_id, **fields)`` with ``.encode()``,
  ``decode(datagram) -> Pdu`` (``PduError`` with the standard's error code for a malformed
  one), ``PayloadCodec`` for DAT payloads and CFG_parameter values, ``next_seq``.
* The slave state machine — ``orchestrator.dcp.states`` (``allowed``, ``enters``,
  ``COMPLETES``, ``RUN_STATES``, ``REQUESTS``, ``NOT_OFFERED``).
* Slave descriptions — ``orchestrator.dcp.dcpx``: ``read_dcpx`` / ``write_dcpx`` (validated
  against the standard's schema), ``SlaveDescription`` (what a slave offers: modes, time
  resolutions, variables; ``resolution_for`` a step), ``description_from_fmu`` (what our
  emulator offers for an FMU), ``serve_over_fmu`` (a device's description served by an FMU).
* The slave role — ``orchestrator.dcp.slave``: ``DcpSlaveServer`` (the protocol engine around
  an FMU) and ``serve`` (``railcosim dcp-slave``); its parts: ``slave_checks`` (whether a
  request is taken), ``slave_config`` (what a master configured), ``slave_data`` (the data
  exchange with the FMU, the counters), ``slave_fmu`` (the FMU served), ``slave_real_time``
  (soft real time).
* The master role — ``orchestrator.dcp.remote_slave``: ``RemoteDcpSlave`` (a remote slave as a
  component of a system, over its ``SlaveLink``); ``orchestrator.dcp.master``: ``parse_swap``
  (``--swap NAME=dcp://…``), ``declared_targets``, ``dcpx_interface`` (a component's ports
  from its .dcpx).
"""
