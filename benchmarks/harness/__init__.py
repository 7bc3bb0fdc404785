"""Harnesses that couple model cores without FMI, for studies, tests, benchmarks and the
figures in docs/: the ATO and traction cores in closed loop, a coder section straight
into a receiver, a train crossing an insulated joint in the rail line core, what a receiver
displays against the code sent (display hold, latencies); and a whole system run into a
throw-away folder for the whole-system benchmarks (runs.py)."""
