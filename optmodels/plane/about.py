"""The registry card of the plane problem (:mod:`optmodels.registry` reads it without
importing the package: keep ``PROBLEM`` a literal)."""

PROBLEM = {
    "name": "plane",
    "order": 1,
    "paper": "000_9c0f4a5f1246cc76.txt",
    "title": "Plane of maneuver by maximum likelihood (Korobochkin)",
    "original": "(1.2)-(1.3)",
    "closed_form": "(1.5)-(1.8)",
    "api": {
        "data": "PlaneData",
        "residuals": ("objective", "constraint_residuals"),
        "solve": "solve",
        "closed_form": "closed_form",
        "estimate": "normal",
    },
}
