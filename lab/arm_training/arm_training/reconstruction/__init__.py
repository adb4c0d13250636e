"""Data generation and training of the reconstruction network (paper Section 3.1, the priors of 3.2)."""
