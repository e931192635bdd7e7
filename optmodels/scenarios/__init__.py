"""Seeded simulators and the papers' own examples."""

from optmodels.scenarios.encounters import Encounter, RadarCell, encounter
from optmodels.scenarios.launcher import TrajectoryScenario, equally_spaced, launcher_release
from optmodels.scenarios.maneuver import (
    PAPER_RADIUS,
    ManeuverScenario,
    ManeuverTrack,
    climb_turn_track,
    paper_plane_example,
    radar_covariances,
    radar_plane,
    two_source_plane,
)
from optmodels.scenarios.radar_network import (
    AircraftPaths,
    RadarNetworkScenario,
    fly_paths,
    fly_paths3d,
    radar_network,
    simulate_plots,
)
from optmodels.scenarios.recording import SimulatedRecording, simulate_recording

__all__ = [
    "PAPER_RADIUS",
    "AircraftPaths",
    "Encounter",
    "ManeuverScenario",
    "ManeuverTrack",
    "RadarCell",
    "RadarNetworkScenario",
    "SimulatedRecording",
    "TrajectoryScenario",
    "climb_turn_track",
    "encounter",
    "equally_spaced",
    "fly_paths",
    "fly_paths3d",
    "launcher_release",
    "paper_plane_example",
    "radar_covariances",
    "radar_network",
    "radar_plane",
    "simulate_plots",
    "simulate_recording",
    "two_source_plane",
]
