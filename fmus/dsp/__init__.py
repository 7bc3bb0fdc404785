"""Signal-processing helpers: analog filter prototypes designed in python-control and
discretised, stateful frame filtering, one-period tables. No FMI."""
