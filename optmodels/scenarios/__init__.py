"""Seeded simulators and the papers' own examples."""

from optmodels.scenarios.launcher import TrajectoryScenario, equally_spaced, launcher_release
from optmodels.scenarios.maneuver import (
    PAPER_RADIUS,
    ManeuverScenario,
    paper_plane_example,
    radar_covariances,
    radar_plane,
    two_source_plane,
)
from optmodels.scenarios.radar_network import (
    AircraftPaths,
    RadarNetworkScenario,
    radar_network,
)

__all__ = [
    "PAPER_RADIUS",
    "AircraftPaths",
    "ManeuverScenario",
    "RadarNetworkScenario",
    "TrajectoryScenario",
    "equally_spaced",
    "launcher_release",
    "paper_plane_example",
    "radar_covariances",
    "radar_network",
    "radar_plane",
    "two_source_plane",
]
