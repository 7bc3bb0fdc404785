"""AtoController FMU facade: ports ↔ AtoCore. No logic here (see core.py, atp.py, driving.py)."""
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, DEFAULT_TIMETABLE, load_line, load_rolling_stock, load_timetable
from fmus.fmi.ports import enumeration_text
from fmus.fmi.slave import FacadeSlave, Port, line_file_port
from fmus.ato_controller.atp import CAB_SIGNAL_MODES, EMERGENCY_INTERVENTION, INTERVENTION_NAMES
from fmus.signalling.aspects import ASPECT_NAMES
from fmus.signalling.ato_modes import AtoMode
from fmus.ato_controller.core import (MAX_DECEL_MPS2, MAX_SPEED_MPS, MODE_ATP_EMERGENCY, MODE_NAMES, TSR_SLOTS, AtoCore,
                                      AtoSettings, event_restrictions, judged_measurements)


class AtoController(FacadeSlave):
    description = "ATP speed supervision from the cab signal + ATO timetable driving, energy-efficient, precise stopping"

    @classmethod
    def declare_ports(cls, build):
        s = AtoSettings()
        return [
            line_file_port(),
            Port("rolling_stock_file", "parameter", "String", start="",
                 description="the ATO's nominal train; empty: the bundled ЧС7 passenger train"),
            Port("timetable_file", "parameter", "String", start="", description="empty: the bundled default timetable"),
            Port("train_category", "parameter", "String", start="",
                 description="passenger | freight | high_speed; empty: the rolling stock's category"),
            Port("strategy", "parameter", "String", start=s.strategy, description="programme | predictive | flat_out"),
            Port("cab_signal", "parameter", "String", start=s.cab_signal,
                 description=" | ".join(f"{name} ({mode.reads()})" for name, mode in CAB_SIGNAL_MODES.items())),
            Port("braking_decel", "parameter", unit="m/s2", start=s.braking_decel_mps2, min=0.0, max=MAX_DECEL_MPS2,
                 description="planned (target) braking deceleration; 0: min(0.5, 0.6 × service)"),
            Port("atp_decel", "parameter", unit="m/s2", start=s.atp_decel_mps2, min=0.0, max=MAX_DECEL_MPS2,
                 description="ATP supervision deceleration; 0: 0.7 × service"),
            Port("speed_margin", "parameter", unit="m/s", start=s.speed_margin_mps, min=0.0, max=MAX_SPEED_MPS,
                 description="the ATO stays this far below every limit"),
            Port("stop_margin", "parameter", unit="m", start=s.stop_margin_m, min=0.0,
                 description="stop this far before a signal at danger"),
            Port("k1", "parameter", unit="1/s", start=s.k1, min=0.0,
                 description="programme strategy: cruise-speed reduction (m/s) per second ahead"),
            Port("k2", "parameter", unit="1", start=s.k2, min=0.0,
                 description="programme strategy: extra traction time per second late"),
            Port("late_threshold", "parameter", unit="s", start=s.late_threshold_s, min=0.0,
                 description="later than this: drive at the maximum permitted speed"),
            Port("early_threshold", "parameter", unit="s", start=s.early_threshold_s, min=0.0,
                 description="earlier than this: hold the programme speed, braking if need be"),
            Port("min_dwell", "parameter", unit="s", start=s.min_dwell_s, min=0.0,
                 description="shortest stand at a stop before departing"),
            Port("stop_window", "parameter", unit="m", start=s.stop_window_m, min=0.0,
                 description="standing at most this far short of the stop point counts as arrived"),
            Port("decoding_latency", "parameter", unit="s", start=s.decoding_latency_s, min=0.0,
                 description="receiver latency the ATP allows after passing a signal"),
            Port("vigilance_period", "parameter", unit="s", start=s.vigilance_period_s, min=0.0,
                 description="vigilance check period under yellow, red-yellow, red and white; 0: no device"),
            Port("vigilance_answer", "parameter", unit="s", start=s.vigilance_answer_s, min=0.001,
                 description="a vigilance warning unanswered this long applies the emergency brake"),
            Port("ato_acknowledges", "parameter", "Boolean", start=s.ato_acknowledges,
                 description="the ATO answers each vigilance check while it drives"),
            # the measurements: an impossible value is a fault the ATP answers with the emergency
            # brake (core.py), never a refused step (docs/ato.md, "Measurement faults")
            Port("x", "input", unit="m", start=0.0, description="head position", bad_input="unit"),
            Port("v", "input", unit="m/s", start=0.0, min=0.0, bad_input="unit",
                 description="below -0.2 m/s or not a number: emergency brake"),
            Port("aspect", "input", "Integer", start=0, min=0, max=4, bad_input="unit",
                 description=enumeration_text(ASPECT_NAMES)),
            Port("code_valid", "input", "Boolean", start=False,
                 description="the receiver shows a received code; false: the fail-safe memory of the last valid code applies"),
            Port("v_permitted", "input", unit="m/s", start=0.0, min=0.0, bad_input="unit",
                 description="digital systems; TVM: the step in force"),
            Port("v_target", "input", unit="m/s", start=0.0, min=0.0, bad_input="unit",
                 description="digital systems; TVM: the next step, at the word's block exit"),
            Port("free_blocks", "input", "Integer", start=0, min=0, bad_input="unit", description="digital systems"),
            Port("cab_code", "input", "Integer", start=0, min=0, bad_input="unit",
                 description=f"{AtoMode.ALSU}: the code the receiver shows (its code output), 0 none"),
            Port("target_distance", "input", unit="m", start=0.0, min=0.0, bad_input="unit",
                 description=f"{AtoMode.TVM430}: from the entry of the word's block to the target point"),
            Port("gradient", "input", unit="1", start=0.0, bad_input="unit",
                 description=f"{AtoMode.TVM430}: most falling gradient to the target point, per mille, + uphill"),
            Port("word_carrier", "input", unit="Hz", start=0.0, min=0.0, bad_input="unit",
                 description=f"{AtoMode.TVM430}, {AtoMode.TVM300}: carrier of the track circuit the shown word came from; 0 none"),
            # temporary restrictions set while running (scenario events; docs/scenarios.md): slot k
            # is in force while tsr_speed[k] > 0 and tsr_end[k] > tsr_start[k]
            Port("tsr_start", "input", unit="m", start=0.0, min=0.0, shape=(TSR_SLOTS,),
                 description="temporary restriction: where the head must be at tsr_speed"),
            Port("tsr_end", "input", unit="m", start=0.0, min=0.0, shape=(TSR_SLOTS,),
                 description="temporary restriction: held until the tail has cleared this point"),
            Port("tsr_speed", "input", unit="m/s", start=0.0, min=0.0, max=MAX_SPEED_MPS, shape=(TSR_SLOTS,),
                 description="temporary restriction speed; 0: slot unused"),
            Port("vigilance_ack", "input", "Boolean", start=False,
                 description="driver's vigilance acknowledgement (a press: false → true answers a check)"),
            # outputs: each from the AtoOutputs field named (core_field; none: the port's own name);
            # the fail-safe ones are what a DCP master shows while the ATO is not heard: full brake
            Port("command", "output", unit="1", min=-1.0, max=1.0, fail_safe=-1.0,
                 description=">0 traction share, <0 brake share (to traction.command)"),
            Port("emergency_brake", "output", "Boolean", start=False, fail_safe=True,
                 description="ATP emergency brake (to traction.emergency_brake)"),
            Port("mode", "output", "Integer", start=0, fail_safe=MODE_ATP_EMERGENCY,
                 description=enumeration_text(MODE_NAMES)),
            Port("v_ref", "output", unit="m/s", core_field="v_ref_mps", description="reference programme speed here"),
            Port("schedule_deviation", "output", unit="s", core_field="schedule_deviation_s", description="late > 0"),
            Port("v_ceiling", "output", unit="m/s", core_field="v_ceiling_mps",
                 description="highest speed the ATO allows itself here"),
            Port("v_atp", "output", unit="m/s", core_field="v_permitted_mps",
                 description="ATP permitted speed at the head (braking curves included)"),
            Port("atp_aspect", "output", "Integer", start=0, core_field="aspect",
                 description="aspect the ATP acts upon (fail-safe rules applied)"),
            Port("atp_intervention", "output", "Integer", start=0, fail_safe=EMERGENCY_INTERVENTION,
                 description=enumeration_text(INTERVENTION_NAMES)),
            Port("atp_interventions", "output", "Integer", start=0, description="ATP interventions so far (service or emergency)"),
            Port("emergency_brakings", "output", "Integer", start=0, description="emergency brakings so far"),
            Port("signals_passed_at_danger", "output", "Integer", start=0,
                 description="signals at danger the head passed so far"),
            Port("max_overspeed", "output", unit="m/s", core_field="max_overspeed_mps",
                 description="largest excess over the line/cab-signal ceiling"),
            Port("stop_index", "output", "Integer", start=1, description="timetable stops reached (1: at the origin)"),
            Port("arrival_time", "output", unit="s", start=-1.0, core_field="arrival_time_s",
                 description="at the last stop reached; −1 before"),
            Port("stop_error", "output", unit="m", core_field="stop_error_m",
                 description="head − stop point at the last arrival"),
            Port("mode_changes", "output", "Integer", start=0, description="traction/coast/brake changes while running"),
            Port("stage", "output", "Integer", start=0, description="timetable stage (0 = first stop to second)"),
            Port("departure_hold", "output", unit="s", core_field="departure_hold_s",
                 description="time standing past a departure time without a valid permissive cab code"),
            Port("vigilance_warning", "output", "Boolean", start=False,
                 description="a vigilance check awaits its acknowledgement"),
            Port("vigilance_brakings", "output", "Integer", start=0,
                 description="emergency brakings for an unanswered vigilance check"),
        ]

    _fault_logged = None      # the input whose fault was last logged

    def make_default_experiment(self):
        return DefaultExperiment(start_time=0.0, stop_time=1200.0, step_size=0.5)

    def create_core(self):
        p = self.param
        self._restriction_slots = None          # the tsr_* inputs the core's restrictions came from
        line = load_line(self.resource_path(p("line_file") or str(DEFAULT_LINE)))
        stock = load_rolling_stock(self.resource_path(p("rolling_stock_file") or str(DEFAULT_ROLLING_STOCK)))
        timetable_path = self.resource_path(p("timetable_file") or str(DEFAULT_TIMETABLE))
        timetable = load_timetable(timetable_path, line)
        settings = AtoSettings(
            strategy=p("strategy"), cab_signal=p("cab_signal"), braking_decel_mps2=p("braking_decel"),
            atp_decel_mps2=p("atp_decel"), speed_margin_mps=p("speed_margin"), stop_margin_m=p("stop_margin"),
            k1=p("k1"), k2=p("k2"), late_threshold_s=p("late_threshold"), early_threshold_s=p("early_threshold"),
            min_dwell_s=p("min_dwell"), stop_window_m=p("stop_window"),
            decoding_latency_s=p("decoding_latency"), vigilance_period_s=p("vigilance_period"),
            vigilance_answer_s=p("vigilance_answer"), ato_acknowledges=bool(p("ato_acknowledges")))
        return AtoCore(line, stock, timetable, timetable_path, p("train_category") or stock.category, settings)

    def unit_handled_inputs(self):
        # the measurements the ATP judges in this cab-signal mode fail safe; the ones it does not
        # read (the aspect with cab_signal = off) are refused out of their declared range
        return judged_measurements(self.param("cab_signal"))

    def publish_initial_outputs(self):
        self.write_outputs(self.core.out)

    def step_core(self, current_time, step_size):
        io = self.io
        core = self.core
        # the restriction slots change only at scenario events: the restrictions made again only
        # then (every step, numpy's calls on three short arrays cost about 25 us of a 0.5 s step)
        slots = (io["tsr_start"].tolist(), io["tsr_end"].tolist(), io["tsr_speed"].tolist())
        if slots != self._restriction_slots:
            self._restriction_slots = slots
            core.set_restrictions(event_restrictions(*slots))
        self.write_outputs(core.step(current_time, step_size, float(io["x"]), float(io["v"]), int(io["aspect"]),
                              bool(io["code_valid"]), float(io["v_permitted"]), float(io["v_target"]),
                              int(io["free_blocks"]), bool(io["vigilance_ack"]), int(io["cab_code"]),
                              float(io["target_distance"]), float(io["gradient"]), float(io["word_carrier"])))
        fault = core.fault[0] if core.fault else None
        if fault != self._fault_logged:                 # once per fault, not every step
            if core.fault:
                self.log(f"AtoController: t={current_time:.6g} s: {core.fault[1]}: emergency brake (fail-safe)",
                         Fmi2Status.warning)
            else:
                self.log(f"AtoController: t={current_time:.6g} s: measurements valid again; the emergency "
                         f"brake holds until standstill", Fmi2Status.warning)
            self._fault_logged = fault
