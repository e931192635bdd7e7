"""The registry card of the fusion problem (:mod:`optmodels.registry` reads it without
importing the package: keep ``PROBLEM`` a literal). The closed form (2) is
``fuse(..., method="closed_form")``, the generic solve ``fuse(..., method="cvxpy")``."""

PROBLEM = {
    "name": "fusion",
    "order": 3,
    "paper": "003_081094e0fa70fc4e.txt",
    "title": "Fusion of two estimates and the accuracy of its weight matrix (Kulyavets et al.)",
    "original": "(1)",
    "closed_form": "(2), (6)",
    "api": {
        "data": None,
        "residuals": ("weight_matrix", "fused_covariance"),
        "solve": "fuse",
        "closed_form": None,
        "estimate": "estimate",
    },
}
