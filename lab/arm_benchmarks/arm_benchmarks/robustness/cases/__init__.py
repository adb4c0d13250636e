"""Malformed and extreme inputs for every node (one module per node, common.py shared;
parameters.py: invalid parameters at start-up), sent over DDS by a Probe, and what each node must do:
stay alive, log a clear error (rate-limited), publish nothing wrong. Each runner returns a report
(plain dict) that tests assert on and bench_robustness writes to results/robustness/summary.json.

Expectations per case: "reject" = nothing may be published for it and an error naming the reason
is expected; "valid" = the node may publish (what it publishes must pass the validator) or reject
it with an error; "silent" = an incomplete input that must produce nothing (no error required).
"""
