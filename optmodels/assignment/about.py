"""The registry card of the assignment problem (:mod:`optmodels.registry` reads it without
importing the package: keep ``PROBLEM`` a literal). The paper has no closed form: its
rule (13)-(14) is the enumeration ``brute_force``."""

PROBLEM = {
    "name": "assignment",
    "order": 5,
    "paper": "004_ce4b6db66d57cef7.txt",
    "title": "ML joint assignment of measurements to unresolved objects (Logachev et al.)",
    "original": "(13)-(14)",
    "closed_form": None,
    "api": {
        "data": "AssignmentData",
        "residuals": ("score", "log_likelihoods"),
        "solve": "solve",
        "closed_form": None,
        "estimate": "assignment",
    },
}
