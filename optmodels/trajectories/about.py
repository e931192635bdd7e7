"""The registry card of the trajectories problem (:mod:`optmodels.registry` reads it
without importing the package: keep ``PROBLEM`` a literal)."""

PROBLEM = {
    "name": "trajectories",
    "order": 2,
    "paper": "002_7b4fdec12ab33196.txt",
    "title": "Least-squares estimation of dependent linear trajectories (Simonova)",
    "original": "(1)",
    "closed_form": "(8)-(9), (12)-(13)",
    "api": {
        "data": "TrajectoryData",
        "residuals": ("objective", "constraint_residuals"),
        "solve": "solve",
        "closed_form": "closed_form",
        "estimate": "theta",
    },
}
