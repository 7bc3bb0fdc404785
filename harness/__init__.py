"""The model cores coupled without FMI, for tests, benchmarks, studies and the figures in docs/:
the ATO and traction cores in closed loop, a coder section straight into a receiver, a train
crossing an insulated joint in the rail line core, what a receiver displays against the code
sent (display hold, latencies). Tests and benchmarks both import it; it imports neither."""
