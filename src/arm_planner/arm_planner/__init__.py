"""MuJoCo twin of the reconstructed scene and MPPI manipulation planning."""
