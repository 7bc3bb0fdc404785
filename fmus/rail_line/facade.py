"""RailLine FMU facade: ports ↔ RailLineCore. No physics here (see core.py, track_circuit.py)."""
from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, load_line, load_rolling_stock
from fmus.fmi.slave import FrameFacadeSlave, Port, line_file_port, sample_rate_port
from fmus.rail_line.core import RailLineCore, RailOutputs, RailSettings
from fmus.rail_line.track_circuit import CircuitParameters

OFF_LINE_M = -1000.0


class RailLine(FrameFacadeSlave):
    description = "Rail line plant: coded track circuits (MNA networks), coil EMF with joints and traction interference, track relays"

    @classmethod
    def declare_ports(cls, build):
        k, m, n = build.sections, build.trains, build.frame
        c = CircuitParameters()
        s = RailSettings()
        return [
            line_file_port(),
            sample_rate_port(s.fs_hz, n),
            Port("carrier", "parameter", unit="Hz", start=s.carrier_hz, min=0.0,
                 description="0: each section's carrier from the line file; else this one (digital: 174.38 / 175 Hz)"),
            Port("tone_band_min", "parameter", unit="Hz", start=s.tone_band_hz[0], min=0.0,
                 description="a code of several tones (ALSU: 125): lowest tone; 0 with tone_band_max 0: one carrier"),
            Port("tone_band_max", "parameter", unit="Hz", start=s.tone_band_hz[1], min=0.0,
                 description="a code of several tones (ALSU: 375): highest tone; the rails follow the √f law "
                             "across the band"),
            # one start for every train: the settings default of the first
            Port("train_length", "parameter", unit="m", start=s.train_length_m[0], shape=(m,), min=1.0,
                 description="train j occupies x_head[j] − train_length[j] … x_head[j]"),
            Port("rolling_stock_file", "parameter", "String", start="", shape=(m,),
                 description="train j's rolling-stock JSON: where its wheelsets are; empty: the bundled default train"),
            Port("coil_offset", "parameter", unit="m", start=s.coil_offset_m, description="coils ahead of the first wheelset"),
            Port("coil_gain", "parameter", unit="H", start=s.coil_gain_h, min=0.0, description="EMF = gain · d(i)/dt"),
            Port("coil_length", "parameter", unit="m", start=s.coil_length_m, min=0.0, description="coil sensitivity length"),
            Port("transformer_ratio", "parameter", unit="1", start=s.transformer_ratio, min=0.0, description="u_tx → rail feed"),
            Port("rail_r", "parameter", unit="Ohm/km", start=c.rail_r_ohm_per_km, min=0.0, description="rail loop resistance"),
            Port("rail_l", "parameter", unit="H/km", start=c.rail_l_h_per_km, min=0.0, description="rail loop inductance"),
            Port("ballast", "parameter", unit="Ohm.km", start=c.ballast_ohm_km, min=0.0,
                 description="minimum (wet) ballast of every section; 0: each section's ballast_ohm_km from the line file"),
            Port("feed_r", "parameter", unit="Ohm", start=c.feed_r_ohm, min=0.0,
                 description="feed end: track transformer and limiting resistor, at the rails"),
            Port("relay_r", "parameter", unit="Ohm", start=c.relay_r_ohm, min=0.0,
                 description="relay end equipment, at the rails"),
            Port("bond_r", "parameter", unit="Ohm", start=c.bond_r_ohm, min=0.0,
                 description="impedance bond signal winding: resistance"),
            Port("bond_l", "parameter", unit="H", start=c.bond_l_h, min=0.0,
                 description="impedance bond signal winding: inductance"),
            Port("shunt_r", "parameter", unit="Ohm", start=c.shunt_r_ohm, min=0.0, description="wheelset shunt"),
            Port("segment", "parameter", unit="m", start=c.segment_m, min=1.0, description="network π-section length"),
            Port("asymmetry_min", "parameter", unit="1", start=s.asymmetry_range[0], min=0.0, max=1.0,
                 description="traction-current asymmetry of the rails: smallest of the per-section draws"),
            Port("asymmetry_max", "parameter", unit="1", start=s.asymmetry_range[1], min=0.0, max=1.0,
                 description="traction-current asymmetry of the rails: largest of the per-section draws"),
            Port("seed", "parameter", "Integer", start=s.seed, description="random draw of each section's asymmetry"),
            Port("coil_mismatch", "parameter", unit="1", start=s.coil_mismatch, min=0.0, max=0.99,
                 description="the two receiver coils' sensitivity difference over their mean (0.05: the tolerance limit)"),
            Port("traction_time_constant", "parameter", unit="s", start=s.traction_time_constant_s, min=0.0,
                 description="lag of the traction current in the rails"),
            Port("relay_pick_up", "parameter", unit="1", start=s.relay_pick_up, min=0.01, max=1.0,
                 description="share of the calibrated reference: the free circuit at minimum ballast and supply"),
            Port("relay_drop_out", "parameter", unit="1", start=s.relay_drop_out, min=0.0, max=1.0,
                 description="share of the calibrated reference; below relay_pick_up"),
            Port("supply_tolerance", "parameter", unit="1", start=s.supply_tolerance, min=0.0, max=0.49,
                 description="± share of the nominal feed the relay calibration covers"),
            Port("shunt_margin", "parameter", unit="1", start=s.shunt_margin, min=0.0,
                 description="required margin: drop-out ≥ (1 + margin) × worst shunt-mode level"),
            Port("relay_pick_up_delay", "parameter", unit="s", start=s.relay_pick_up_delay_s, min=0.0,
                 description="a track relay picks up once its level has stayed at or above relay_pick_up this long"),
            Port("relay_drop_out_delay", "parameter", unit="s", start=s.relay_drop_out_delay_s, min=0.0,
                 description="a track relay drops out once its level has stayed at or below relay_drop_out this long"),
            Port("u_tx", "input", unit="V", shape=(k, n), frame=True, description="code voltage per section (coder)"),
            Port("x_head", "input", unit="m", start=OFF_LINE_M, shape=(m,), description="first wheelset at the step start; off the line: ignored"),
            Port("v", "input", unit="m/s", start=0.0, shape=(m,),
                 description="train speed at the step start: x(t) = x_head + v·(t − step start) until the next step"),
            Port("i_traction", "input", unit="A", start=0.0, shape=(m,),
                 description="each train's traction line current (return current in the rails), positive drawn"),
            Port("broken_rail_at", "input", unit="m", start=-1.0, description="fault: broken rail position; < 0 none"),
            Port("ballast_override", "input", unit="Ohm.km", start=0.0, shape=(k,), description="fault: wet ballast; 0 = design"),
            Port("feed_open", "input", "Boolean", start=False, shape=(k,), description="fault: bond disconnected / feed failed"),
            Port("e_coil", "output", unit="V", shape=(m, n), frame=True, description="receiver coil EMF per train"),
            Port("occupied", "output", "Boolean", start=False, shape=(k,),
                 description="track relay of each section down (occupied, or a fault) at the frame end"),
            Port("i_axle", "output", unit="A", shape=(m,), description="rms code current under the first wheelset"),
            Port("off_line", "output", "Boolean", start=True, shape=(m,),
                 description="no coil of train j over the line during the frame"),
            Port("coil_section", "output", "Integer", start=0, shape=(m,),
                 description="section (1-based) under each train's coil at the frame end, 0 none"),
        ]

    def make_default_experiment(self):
        return self.frame_experiment(RailSettings.fs_hz)

    def create_core(self):
        p, io = self.param, self.io
        circuit = CircuitParameters(
            rail_r_ohm_per_km=p("rail_r"), rail_l_h_per_km=p("rail_l"), ballast_ohm_km=p("ballast"), feed_r_ohm=p("feed_r"),
            relay_r_ohm=p("relay_r"), bond_r_ohm=p("bond_r"), bond_l_h=p("bond_l"), shunt_r_ohm=p("shunt_r"),
            segment_m=p("segment"))
        settings = RailSettings(
            fs_hz=p("fs"), circuit=circuit, transformer_ratio=p("transformer_ratio"), coil_offset_m=p("coil_offset"),
            coil_gain_h=p("coil_gain"), coil_length_m=p("coil_length"),
            train_length_m=tuple(float(x) for x in io["train_length"]),
            wheelset_offsets_m=tuple(load_rolling_stock(self.resource_path(name or str(DEFAULT_ROLLING_STOCK))).wheelset_offsets_m
                                     for name in io["rolling_stock_file"]),
            asymmetry_range=(p("asymmetry_min"), p("asymmetry_max")), seed=p("seed"), coil_mismatch=p("coil_mismatch"),
            traction_time_constant_s=p("traction_time_constant"),
            relay_pick_up=p("relay_pick_up"), relay_drop_out=p("relay_drop_out"),
            relay_pick_up_delay_s=p("relay_pick_up_delay"), relay_drop_out_delay_s=p("relay_drop_out_delay"),
            supply_tolerance=p("supply_tolerance"), shunt_margin=p("shunt_margin"), carrier_hz=p("carrier"),
            tone_band_hz=(p("tone_band_min"), p("tone_band_max")))
        line = load_line(self.resource_path(p("line_file") or str(DEFAULT_LINE)))
        core = RailLineCore(line, self.build.sections, self.build.trains, self.build.frame, settings)
        # the core writes its outputs straight into the output ports, each its declared core field
        core.bind_outputs(RailOutputs(**{field: io[port] for port, field in self.output_fields}))
        self.require_frame_step(settings.fs_hz)
        # the trains' initial positions (the traction units publish x0 in initialisation mode):
        # trains on the line occupy their circuits from the first sample
        core.start(io["x_head"])
        return core

    def publish_initial_outputs(self):
        self.io["off_line"][...] = True

    def step_core(self, current_time, step_size):
        io = self.io
        core = self.core
        core.set_faults(float(io["broken_rail_at"]), io["ballast_override"], io["feed_open"])
        core.step(current_time, io["u_tx"], io["x_head"], io["v"], io["i_traction"])     # into the output ports
