"""WaysideCoder FMU facade: ports ↔ the core of the cab system named by ``system`` (cores.py:
WaysideCoderCore for ALSN, AlsuCoderCore, Tvm430CoderCore, DigitalCoderCore for ALS-EN and
FIRE_DQPSK, …). No logic here."""
from fmus.signalling import cab_systems
from fmus.data.loader import DEFAULT_LINE, load_line
from fmus.fmi.ports import enumeration_text
from fmus.fmi.slave import FrameFacadeSlave, Port, line_file_port, cab_system_port, sample_rate_port
from fmus.signalling.block_rules import SIGNAL_NAMES
from fmus.wayside_coder.core import STATUS_NAMES, CoderSettings, bind_outputs
from fmus.wayside_coder.cores import make_coder


class WaysideCoder(FrameFacadeSlave):
    description = ("Wayside cab-signal coder: automatic-block aspects from occupancy; ALSN KPT-5/KPT-7 transmitters, "
                   "ALSU two-of-six tone generators, TVM-430 word or TVM-300 sub-frequency generators on UM71 carriers, or "
                   "ALS-EN / FIRE_DQPSK digital generators (2-out-of-2) per section")

    @classmethod
    def declare_ports(cls, build):
        k, n = build.sections, build.frame
        s = CoderSettings()
        return [
            line_file_port(),
            Port("codes_file", "parameter", "String", start="",
                 description="code tables (JSON); empty: the bundled ones (ALSN KPT-5/KPT-7 timings, ALSU tone pairs, "
                             "TVM-430 word tables, TVM-300 sub-frequency table)"),
            cab_system_port(cab_systems.NAMES, cab_systems.DEFAULT.name),
            sample_rate_port(s.fs_hz, n),
            Port("carrier", "parameter", unit="Hz", start=s.carrier_hz, min=0.0,
                 description="0: ALSN each section's carrier from the line file, digital the system's "
                             "(ALS-EN 174.38 Hz, FIRE_DQPSK 175 Hz), ALSU its six tones, TVM430 and TVM300 each section's "
                             "from the line file; else this carrier for all (ALSN, digital)"),
            Port("amplitude", "parameter", unit="V", start=s.amplitude_v, min=0.0,
                 description="peak transmitter voltage (ALSU: of each tone)"),
            Port("address", "parameter", "Integer", start=0, min=0, max=7,
                 description="TVM430: network address sent in every word (one of the word tables' addresses); "
                             "0: the tables' first"),
            Port("block_aspects", "parameter", "Integer", start=s.block_aspects, min=3, max=4,
                 description="automatic block with 3 or 4 signal aspects"),
            Port("coding", "parameter", "String", start=s.coding, description="always | on_occupation"),
            Port("switch_on_delay", "parameter", unit="s", start=s.switch_on_delay_s, min=0.0,
                 description="coding on_occupation: a section is coded this long after it became occupied"),
            Port("timing_scale", "parameter", unit="1", start=s.timing_scale, min=0.5, max=2.0,
                 description="all code timings × this (transmitter drift)"),
            Port("relay_time_constant", "parameter", unit="s", start=s.relay_time_constant_s, min=0.0,
                 description="transmitter-relay switching transient; 0: ideal keying"),
            Port("seed", "parameter", "Integer", start=s.seed, description="random cam / symbol-clock phase per section"),
            Port("track_parity", "parameter", "Integer", start=s.track_parity, min=0, max=1,
                 description="digital: parity of this track sent in every message (1 odd, 0 even)"),
            Port("generator_bandwidth", "parameter", unit="Hz", start=s.generator_bandwidth_hz, min=0.0,
                 description="digital: generator band-pass width; 0: 10/3 × the symbol rate"),
            Port("occupied", "input", "Boolean", start=False, shape=(k,),
                 description="track relay of each section down (from the rail line)"),
            Port("fault_main", "input", "Boolean", start=False,
                 description="the main transmitter / controller failed (found by its self-test)"),
            Port("fault_reserve", "input", "Boolean", start=False,
                 description="the reserve transmitter / controller failed (found by its self-test)"),
            Port("wrong_command_main", "input", "Integer", start=0, min=0,
                 description="digital: 0 healthy, else the main controller computes this command everywhere"),
            Port("wrong_command_reserve", "input", "Integer", start=0, min=0,
                 description="digital: 0 healthy, else the reserve controller computes this command everywhere"),
            Port("u_tx", "output", unit="V", shape=(k, n), frame=True, description="transmitter voltage into each section"),
            Port("code_tx", "output", "Integer", start=0, shape=(k,),
                 description="code in the frame's last sample, 0 none; ALSN 2 КЖ, 3 Ж, 4 З; ALSU code 1-13; "
                             "FIRE_DQPSK command 1-16; ALS-EN KLUB register; TVM430 the 27-bit word; TVM300 the sub-frequency 1-18"),
            Port("signal", "output", "Integer", start=0, shape=(k,),
                 description="signal at each section's exit: " + enumeration_text(SIGNAL_NAMES)),
            Port("status", "output", "Integer", start=0, description=enumeration_text(STATUS_NAMES)),
        ]

    def make_default_experiment(self):
        return self.frame_experiment(CoderSettings.fs_hz)

    def create_core(self):
        p = self.param
        cab_systems.check_name(p("system"))
        line = load_line(self.resource_path(p("line_file") or str(DEFAULT_LINE)))
        settings = CoderSettings(
            fs_hz=p("fs"), carrier_hz=p("carrier"), amplitude_v=p("amplitude"), block_aspects=p("block_aspects"),
            coding=p("coding"), switch_on_delay_s=p("switch_on_delay"), timing_scale=p("timing_scale"),
            relay_time_constant_s=p("relay_time_constant"), seed=p("seed"), track_parity=p("track_parity"),
            generator_bandwidth_hz=p("generator_bandwidth"))
        codes_file = p("codes_file")
        core = make_coder(p("system"), line, self.build.sections, self.build.frame, settings,
                          self.resource_path(codes_file) if codes_file else None, p)
        self.require_frame_step(settings.fs_hz)
        bind_outputs(core, self.io["u_tx"], self.io["code_tx"], self.io["signal"])    # written in place
        return core

    def step_core(self, current_time, step_size):
        io = self.io
        out = self.core.step(current_time, io["occupied"], bool(io["fault_main"]), bool(io["fault_reserve"]),
                             int(io["wrong_command_main"]), int(io["wrong_command_reserve"]))
        if out.status != io["status"].item():           # u_tx, code_tx and signal are written in place
            io["status"][...] = out.status
