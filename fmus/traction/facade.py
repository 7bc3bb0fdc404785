"""Traction FMU facade: ports ↔ TractionCore. No physics here (see core.py)."""
from pythonfmu.default_experiment import DefaultExperiment

from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, load_line, load_rolling_stock
from fmus.fmi.slave import FacadeSlave, Port, line_file_port, keyword_defaults
from fmus.traction.core import MAX_LINE_M, MAX_PANTOGRAPH_V, MAX_SPEED_MPS, TractionCore


class Traction(FacadeSlave):
    description = "Train longitudinal dynamics, traction/brake characteristics, energy and traction current"

    @classmethod
    def declare_ports(cls, build):
        s = keyword_defaults(TractionCore)
        return [
            Port("rolling_stock_file", "parameter", "String", start="",
                 description="rolling-stock JSON; empty: the bundled ЧС7 passenger train"),
            line_file_port(),
            Port("x0", "parameter", unit="m", start=s["x0_m"], min=0.0, max=MAX_LINE_M,
                 description="initial head position; within the line"),
            Port("v0", "parameter", unit="m/s", start=s["v0_mps"], min=0.0, max=MAX_SPEED_MPS, description="initial speed"),
            Port("pantograph_voltage", "parameter", unit="V", start=s["pantograph_voltage_v"], min=0.0,
                 max=MAX_PANTOGRAPH_V,
                 description="catenary voltage: sets the line current and the effort characteristic; 0: the line's nominal voltage"),
            Port("mass_scale", "parameter", unit="1", start=s["mass_scale"], min=0.1, max=10.0,
                 description="the rolling stock's mass × this (robustness studies)"),
            Port("resistance_scale", "parameter", unit="1", start=s["resistance_scale"], min=0.1, max=10.0,
                 description="the rolling stock's running resistance × this (robustness studies)"),
            Port("max_substep", "parameter", unit="s", start=s["max_substep_s"], min=0.001, max=10.0,
                 description="longest RK4 sub-step inside a communication step"),
            Port("command", "input", unit="1", start=0.0, min=-1.0, max=1.0, bad_input="clamp",
                 description=">0 traction share, <0 brake share; outside −1..1 clamped and counted"),
            Port("emergency_brake", "input", "Boolean", start=False,
                 description="emergency brake applied (overrides command)"),
            # outputs: each from the TractionOutputs field named (core_field; none: the port's name)
            Port("x", "output", unit="m", core_field="x_m", description="head position along the line"),
            Port("v", "output", unit="m/s", core_field="v_mps", description="speed, never negative"),
            Port("a", "output", unit="m/s2", core_field="a_mps2", description="acceleration"),
            Port("force_traction", "output", unit="N", core_field="force_traction_n",
                 description="tractive effort at the wheels"),
            Port("force_brake", "output", unit="N", core_field="force_brake_n", description="electric + pneumatic"),
            Port("i_traction", "output", unit="A", core_field="i_traction_a",
                 description="line current, positive drawn"),
            Port("energy", "output", unit="J", core_field="energy_j",
                 description="net energy from the line (drawn − returned)"),
            Port("energy_returned", "output", unit="J", core_field="energy_returned_j",
                 description="energy returned to the line by regenerative braking"),
            Port("notch", "output", "Integer", start=0, description="traction controller position; 0: no traction"),
            Port("brake_step", "output", "Integer", start=0, description="0 released … steps, steps+1 emergency"),
            Port("commands_clamped", "output", "Integer", start=0,
                 description="commands outside −1…1 received (each clamped)"),
            Port("stop_time", "output", unit="s", core_field="stop_time_s",
                 description="when the train last stopped; −1 while moving"),
            Port("off_line", "output", "Boolean", start=False, description="head position outside the line"),
        ]

    def make_default_experiment(self):
        return DefaultExperiment(start_time=0.0, stop_time=600.0, step_size=0.5)

    def create_core(self):
        stock_file = self.param("rolling_stock_file") or str(DEFAULT_ROLLING_STOCK)
        line_file = self.param("line_file") or str(DEFAULT_LINE)
        return TractionCore(load_rolling_stock(self.resource_path(stock_file)),
                            load_line(self.resource_path(line_file)),
                            x0_m=self.param("x0"), v0_mps=self.param("v0"),
                            pantograph_voltage_v=self.param("pantograph_voltage"),
                            mass_scale=self.param("mass_scale"), resistance_scale=self.param("resistance_scale"),
                            max_substep_s=self.param("max_substep"))

    def enter_initialization_mode(self):
        super().enter_initialization_mode()
        # the initial state is known once the parameters are: a unit that needs the train's
        # position during initialisation (the rail line's initial occupancy) reads it here
        self.io["x"][...] = self.param("x0")
        self.io["v"][...] = self.param("v0")

    def publish_initial_outputs(self):
        self.write_outputs(self.core._publish(0.0))

    def step_refusal(self, current_time, step_size):
        return self.core.step_refusal(step_size)

    def step_core(self, current_time, step_size):
        io = self.io
        self.write_outputs(self.core.step(current_time, step_size, float(io["command"]), bool(io["emergency_brake"])))
