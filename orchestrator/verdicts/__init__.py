"""The railway verdicts of a run: ``verdict.py`` judges the trains and the receivers while the run
goes (the per-train and per-receiver parts of summary.json), ``system_checks.py`` refuses a
system whose railway data cannot run before any component is made. Reads the engine's graph and
the FMU-side libraries (``fmus.signalling``, ``fmus.data``); the engine never imports this package.
"""
