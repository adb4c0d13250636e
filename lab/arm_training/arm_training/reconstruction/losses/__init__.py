"""Training losses: GenRe-style reconstruction loss and ARM's stability and connectivity priors."""

from arm_training.reconstruction.losses.connectivity_prior import (
    connectivity_log_probability,
    connectivity_loss,
    connectivity_value_and_gradient,
)
from arm_training.reconstruction.losses.reconstruction_loss import reconstruction_loss, surface_shell
from arm_training.reconstruction.losses.stability_prior import (
    stability_log_probability,
    stability_loss,
    stability_value_and_gradient,
)

__all__ = [
    "connectivity_log_probability",
    "connectivity_loss",
    "connectivity_value_and_gradient",
    "reconstruction_loss",
    "stability_log_probability",
    "stability_loss",
    "stability_value_and_gradient",
    "surface_shell",
]
