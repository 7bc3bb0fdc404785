"""Systems written from Python: ``chain.py`` the building blocks (a train and its ATO, the signal
chain, each cab system's settings, SSDs from the committed contract manifests), ``shipped.py``
the shipped systems of ssp/, ``queued.py`` N trains queued behind a system's start (the headway
trials), ``new_system.py`` ``railcosim new`` (a system from a line file or a railML file)."""
