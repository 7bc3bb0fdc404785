"""Build tooling, never bundled into an FMU: the FMU build pipeline (``builder``), the
committed port manifests (``contract``) and .ssp packing (``packing``)."""
