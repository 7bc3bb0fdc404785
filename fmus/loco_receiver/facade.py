"""LocoReceiver FMU facade: ports ↔ the core of the cab system named by ``system`` (cores.py:
LocoReceiverCore for ALSN, AlsuReceiverCore, Tvm430ReceiverCore, DigitalReceiverCore for ALS-EN and
FIRE_DQPSK, …). No logic here."""
from fmus.errors import FmuInputError
from fmus.signalling import alsn, cab_systems
from fmus.signalling import aspects as sig
from fmus.loco_receiver.tvm430 import Tvm430ReceiverSettings
from fmus.fmi.ports import enumeration_text
from fmus.fmi.slave import FrameFacadeSlave, Port, cab_system_port, sample_rate_port
from fmus.loco_receiver.core import CHANNELS, ReceiverSettings
from fmus.loco_receiver.cores import receiver_kind
from fmus.loco_receiver.digital_receiver import DigitalReceiverSettings
from fmus.loco_receiver.parameters import receiver_settings


class LocoReceiver(FrameFacadeSlave):
    description = ("Locomotive cab-signal receiver: ALSN (gain control, band-pass, envelope, impulse relay, KPT "
                   "decoder), ALSU (six tone channels, exactly two tones), TVM430 (the track's two carriers, FM "
                   "discriminator, 27 tones by least squares, word check), TVM300 (the same front end, exactly one "
                   "of 18 sub-frequencies) or ALS-EN / FIRE_DQPSK (correlation demodulator, code check, 2-out-of-3 "
                   "channels)")

    @classmethod
    def declare_ports(cls, build):
        n = build.frame
        s, d = ReceiverSettings(), DigitalReceiverSettings()     # ALSN and digital-only defaults
        tvm = Tvm430ReceiverSettings()
        return [
            cab_system_port(cab_systems.NAMES, cab_systems.DEFAULT.name),
            Port("codes_file", "parameter", "String", start="",
                 description="ALSU: the code table (tone pairs, readings); TVM430: the word tables; TVM300: the "
                             "sub-frequency table; empty: the bundled one"),
            Port("carrier", "parameter", unit="Hz", start=s.carrier_hz, min=0.0,
                 description="0: the system's (ALSN 50 Hz, ALS-EN 174.38 Hz, FIRE_DQPSK 175 Hz); ALSN 25, 50 or 75 Hz; "
                             "ALSU, TVM430 and TVM300 (their track's carriers): 0 only"),
            sample_rate_port(s.fs_hz, n),
            Port("train_category", "parameter", "String", start=s.train_category,
                 description="passenger | freight | high_speed"),
            Port("v_max", "parameter", unit="m/s", start=s.v_max_mps, min=0.0,
                 description="speed reported on green; 0: the category's maximum"),
            Port("filter_order", "parameter", "Integer", start=s.filter_order, min=1, max=8,
                 description="Butterworth prototype order (band-pass order is twice this)"),
            Port("filter_bandwidth", "parameter", unit="Hz", start=s.filter_bandwidth_hz, min=0.0,
                 description="band-pass width; 0: ALSN 0.4 × carrier, digital 10/3 × the symbol rate, ALSU 10 Hz per tone"),
            Port("agc_limit", "parameter", unit="V", start=s.agc_limit_v, min=0.0,
                 description="input amplitude where gain reduction starts"),
            Port("agc_recovery", "parameter", unit="dB/s", start=s.agc_recovery_db_per_s, min=0.0,
                 description="gain recovery rate"),
            Port("pick_up", "parameter", unit="V", start=s.pick_up_v, min=0.0,
                 description="relay pick-up (input-referred envelope); ALSU: a tone present above it"),
            Port("drop_out", "parameter", unit="V", start=s.drop_out_v, min=0.0,
                 description="relay drop-out (input-referred envelope); below pick_up"),
            Port("inertia", "parameter", unit="s", start=s.inertia_s, min=0.0,
                 description="longest loss of code the display bridges, from the last code supporting it; "
                             "0: the system's (ALSN 5.5 s, the equipment's inertia; ALSU 1 s; TVM430 3.5 s; TVM300 2.12 s; digital: none)"),
            Port("track_parity", "parameter", "Integer", start=d.track_parity, min=0, max=1,
                 description="digital: parity of the track the train runs on (messages of the other are discarded)"),
            Port("limiter", "parameter", unit="V", start=d.limiter_v, min=0.0, description="digital: input limiter; 0 none"),
            Port("min_level", "parameter", unit="V", start=d.min_level_v, min=0.0,
                 description="digital: squelch, carrier amplitude below which nothing is decided"),
            Port("track", "parameter", "Integer", start=tvm.track, min=1, max=2,
                 description="TVM430, TVM300: the track whose carriers are decoded (1: 1700 / 2300 Hz, 2: 2000 / 2600 Hz)"),
            Port("channel_fault", "input", "Integer", start=0, shape=(CHANNELS,), min=0, max=3,
                 description="digital, per channel: 0 ok, 1 failed (self-test), 2 stuck most permissive, 3 silent"),
            Port("e_coil", "input", unit="V", shape=(n,), frame=True, description="coil EMF frame"),
            # outputs: each from the ReceiverOutputs field named (core_field; none: the port's own
            # name); the fail-safe ones are what a DCP master shows while the receiver is not
            # heard: the no-code indication, and no speed at all (more restrictive than white's)
            Port("aspect", "output", "Integer", start=0, fail_safe=sig.WHITE,
                 description=enumeration_text(cab_systems.ASPECT_LABELS)),
            Port("code", "output", "Integer", start=0, fail_safe=alsn.NO_CODE,
                 description="ALSN: last decoded cycle (0 none/invalid, 2 КЖ, 3 Ж, 4 З); ALSU and digital: the code shown, "
                             "TVM430: the 27-bit word shown; TVM300: the sub-frequency shown (1-18); 0 none"),
            Port("code_valid", "output", "Boolean", start=False, fail_safe=False,
                 description="the indication shown is a received code (held ones included); false: the no-code indication"),
            Port("v_permitted", "output", unit="m/s", core_field="v_permitted_mps", fail_safe=0.0,
                 description="speed permitted from now on, per train category (white 40 km/h, red 20 km/h)"),
            Port("v_target", "output", unit="m/s", core_field="v_target_mps", fail_safe=0.0,
                 description="speed to be reached at the next signal; 0: stop before it"),
            Port("free_blocks", "output", "Integer", start=0, fail_safe=0,
                 description="free block sections ahead: ALSN 2 green, 1 yellow, 0 otherwise; digital 0-6"),
            Port("level", "output", unit="V", core_field="level_v",
                 description="carrier amplitude at the coil (peak-hold, 1 s release)"),
            Port("errors", "output", "Integer", start=0, description="invalid cycles"),
            Port("decoded_codes", "output", "Integer", start=0, description="valid cycles"),
            Port("transmitter", "output", "Integer", start=0, description="5 (KPT-5) or 7 (KPT-7) of the last valid cycle"),
            Port("joints", "output", "Integer", start=0, description="changes of transmitter type (joints passed)"),
            Port("relay", "output", "Boolean", start=False, fail_safe=False,
                 description="ALSN: impulse relay state at the frame end; digital: carrier above the squelch"),
            Port("channel_code", "output", "Integer", start=0, shape=(CHANNELS,), core_field="channel_codes",
                 description="digital: each channel's command (raw id), 0 none"),
            Port("foreign", "output", "Integer", start=0, description="digital: messages of the other track discarded"),
            Port("target_distance", "output", unit="m", core_field="target_distance_m",
                 description="TVM430: distance to the target point from the entry of the block whose word is shown; 0 no word"),
            Port("gradient", "output", unit="1", core_field="gradient_permille",
                 description="TVM430: the word's gradient in ‰ (+ uphill), the most falling up to the target; 0 no word"),
            Port("word_carrier", "output", unit="Hz", core_field="word_carrier_hz",
                 description="TVM430, TVM300: the carrier the word or code shown came from; 0 none"),
        ]

    def make_default_experiment(self):
        return self.frame_experiment(ReceiverSettings.fs_hz)

    def create_core(self):
        cab = cab_systems.lookup(self.param("system"))
        kind = receiver_kind(cab.name)
        codes_file = self.param("codes_file")
        system = cab.system(self.resource_path(codes_file) if codes_file and cab.codes_file else None)
        settings = receiver_settings(cab.name, self.scalar_parameters())
        if kind.own_carriers and self.param("carrier"):
            raise FmuInputError(f"parameter carrier: {self.param('carrier'):g} Hz, but {kind.own_carriers}")
        core = kind.make_core(self.build.frame, settings, system)
        self.require_frame_step(settings.fs_hz)
        return core

    def publish_initial_outputs(self):
        self.write_outputs(self.core.out)

    def step_core(self, current_time, step_size):
        io = self.io
        self.write_outputs(self.core.step(current_time, io["e_coil"], io["channel_fault"]))
