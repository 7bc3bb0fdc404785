"""Errors the model cores raise. No dependencies: every core, the data layer and the
orchestrator's analysis import this without pulling in any FMI library."""


class FmuInputError(ValueError):
    """A parameter or data file given to an FMU is invalid; the message names what and where."""
