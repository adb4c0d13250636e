"""reconstruction_node's settings: the reconstruction's (ReconstructionSettings) and the node's.

The node declares the settings marked as parameters (arm_core.settings); config/reconstruction_node.yaml
is rendered from this dataclass."""

from __future__ import annotations

from dataclasses import dataclass, field

from arm_core.settings import GoalPauseSettings, cpu_niceness_setting, setting

from .pipeline import ReconstructionSettings


@dataclass
class ReconstructionNodeConfig:
    reconstruction: ReconstructionSettings = field(default_factory=ReconstructionSettings)
    goal_pause: GoalPauseSettings = field(default_factory=GoalPauseSettings)
    cpu_niceness: int = cpu_niceness_setting()
    frame_reliability: str = setting(
        "reliable",
        "QoS reliability of the arm/segmented_frame subscription",
        choices=("reliable", "best_effort"),
        parameter=True,
    )
    max_rate_hz: float = setting(
        0.0,
        "Most frames reconstructed per second, wall clock (0: every frame; lower it to leave CPU to planning)",
        0.0,
        100.0,
        parameter=True,
    )
    marker_alpha: float = setting(0.8, "Opacity of the RViz markers", 0.0, 1.0, parameter=True)
