"""The ATO's ``cab_signal`` modes by name, apart from the registry of cab systems
(cab_systems.py, which names each system's mode) so that a unit without a signal chain (the
ATO) reads them without loading the signalling library's tables and filters."""


class AtoMode:
    """The ATO's ``cab_signal`` modes: how its ATP reads the receiver's indication
    (fmus/ato_controller/atp.py). One mode may serve several systems (``digital``: ALS-EN and
    FIRE_DQPSK); ``off`` runs without a cab signal."""

    ALSN = "ALSN"
    ALSU = "ALSU"
    DIGITAL = "digital"
    TVM430 = "TVM430"
    TVM300 = "TVM300"
    OFF = "off"
    ALL = (ALSN, ALSU, DIGITAL, TVM430, TVM300, OFF)
