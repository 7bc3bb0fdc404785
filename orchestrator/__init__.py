"""railcosim orchestrator: SSP loading (ssp), system graph (graph), master algorithm (master),
observers (observers), FMU/in-process slaves (fmu), one run (run), CLI (cli)."""
