"""The registry card of the bias-field problem (:mod:`optmodels.registry` reads it without
importing the package: keep ``PROBLEM`` a literal)."""

PROBLEM = {
    "name": "biasfield",
    "order": 4,
    "paper": "001_d6b2428a10e192f8.txt",
    "title": "Radar bias fields: the smoothest field on the uncertainty sets (Bedin)",
    "original": "(8)-(10)",
    "closed_form": "(11)",
    "api": {
        "data": "FieldData",
        "residuals": ("problem.objective", "verify.kkt_residuals"),
        "solve": "solve",
        "closed_form": "closed_form",
        "estimate": "field",
    },
}
