"""The FMU ``railcosim dcp-slave`` serves, driven through orchestrator/fmu.py's slaves as in a
run: made afresh when a session needs a new instance, initialised once per session, stepped
in units of the session's time resolution, terminated and freed without ever ending the slave.
"""
from __future__ import annotations

from fractions import Fraction
from typing import Callable, Optional, Tuple

from orchestrator.dcp import dcpx
from orchestrator.errors import SimulationError, UserError


class ServedFmu:
    """One slave's FMU (``make_fmu`` makes an instance; ``log`` reports what the FMU refused at
    the end of a session)."""

    def __init__(self, make_fmu: Callable, log: Callable[[str], None]):
        self.make_fmu, self.log = make_fmu, log
        self.fmu = None
        self.fresh = True               # made and not yet configured: STC_configure may take it as it is
        self.new_session()

    def new_session(self) -> None:
        """Simulation time back to 0, the FMU to be initialised again."""
        self.initialised = False
        self.units = 0                 # simulation time in resolution units since the start

    def load(self) -> None:
        """A fresh instance, instantiated (the previous one freed)."""
        self.free()
        self.fmu = self.make_fmu()
        self.fmu.instantiate()

    def initialise(self) -> None:
        """The inputs written, initialisation left once per session, the outputs read."""
        self.fmu.write_inputs()
        if not self.initialised:
            self.fmu.exit_initialization()
            self.initialised = True
        self.fmu.read_outputs()

    def own_step_s(self) -> Optional[Fraction]:
        """The FMU's own step (None: it states none), exact to the nanosecond."""
        step_s = self.fmu.interface.default_step_s if self.fmu is not None else None
        return Fraction(round(step_s * dcpx.NS_PER_SECOND), dcpx.NS_PER_SECOND) if step_s else None

    def own_step_units(self, resolution: Tuple[int, int]) -> Optional[int]:
        """The FMU's own step in units of the time resolution (None: not a whole number)."""
        step_s = self.own_step_s()
        if step_s is None:
            return None
        units = step_s / Fraction(*resolution)
        return int(units) if units.denominator == 1 else None

    def step(self, steps: int, resolution: Tuple[int, int]) -> None:
        """Advance the FMU by ``steps`` resolution units: in steps of its own size when they
        divide the request (an FMU that accepts only its own step, as ours, can then be asked
        for several at once), else in one."""
        num, den = resolution
        own = self.own_step_units(resolution)
        parts = (steps // own, own) if own and steps > own and steps % own == 0 else (1, steps)
        self.fmu.write_inputs()
        for _ in range(parts[0]):
            self.fmu.do_step(self.units * num / den, parts[1] * num / den)
            self.units += parts[1]
        self.fmu.read_outputs()

    def terminate(self) -> None:
        if self.fmu is not None:
            try:
                self.fmu.terminate()
            except (SimulationError, UserError) as error:
                self.log(f"terminate: {error}")
        self.fresh = False

    def free(self) -> None:
        if self.fmu is not None:
            fmu, self.fmu = self.fmu, None
            try:
                fmu.free()
            except Exception as error:      # an FMU's own failure to free: report, keep serving
                self.log(f"freeInstance: {error}")
