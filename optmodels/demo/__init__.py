"""``optmodels demo``: the papers' examples, with figures and a short report each."""

from optmodels.demo.assignment import run_assignment_demo
from optmodels.demo.biasfield import run_biasfield_demo
from optmodels.demo.fusion import run_fusion_demo
from optmodels.demo.plane import run_plane_demo
from optmodels.demo.trajectories import run_trajectories_demo

__all__ = [
    "run_assignment_demo",
    "run_biasfield_demo",
    "run_fusion_demo",
    "run_plane_demo",
    "run_trajectories_demo",
]
