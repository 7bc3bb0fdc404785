"""Railway knowledge applied to runs: the verdicts of summary.json, the report's pictures,
the generation of the shipped systems. Uses the engine's graph and the FMU-side libraries
(``fmus.signalling``, ``fmus.data``); the engine never imports this package."""
