"""Named unit conversions and physical constants, defined once for cores, facades and the
analysis. Ports and cores work in SI; km/h and kWh appear only in data files, tables from the
sources and reports. No dependencies."""

MPS_PER_KMH = 1.0 / 3.6         # a speed in km/h times this is in m/s
KMH_PER_MPS = 3.6               # a speed in m/s times this is in km/h
J_PER_KWH = 3.6e6               # an energy in kWh times this is in J
STANDARD_GRAVITY_MPS2 = 9.81    # the value the rolling-stock formulas of docs/traction.md use
