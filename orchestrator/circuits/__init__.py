"""The track circuits checked outside the rail line core: ``rail_setup.py`` a system's rail line
and trains at an instant, ``netlist.py`` one track circuit as a SPICE netlist (``railcosim
netlist``), ``ngspice.py`` ngspice run as a subprocess, ``crosscheck.py`` the rail line core's
figures against ngspice's (``railcosim crosscheck spice``, docs/rail_line.md)."""
