"""Robustness harness shared by tests/robustness and bench_robustness, one job per module:
nodes (which nodes, their checkpoint), probe (an in-process DDS probe), logs (error-log analysis),
validators (what the nodes publish must be well formed), messages and frames (inputs rendered by the
simulator), bags (camera bags for load runs, broken bags), parameters (parameter services and node
conventions), cases/ (malformed inputs, one module per node), load (load and fault runs of the
full graph).
Node processes come from arm_ros.processes."""
