"""Training of the reconstruction network, one job per module: config (variants, hyper-parameters
and loss terms), evaluation (held-out voxel metrics), plots (training curves), distributed
(torchrun processes and devices), loop (the resumable training loop), measure (perf figures).
The `train` console script (arm_training.reconstruction.train) is its command line."""
