"""Solver and formulation comparisons against the papers' closed forms.

Each problem contributes a module with a ``run(...)`` returning tidy rows (columns as in
DESIGN.md); :func:`solvers_cmp.report.write_report` writes the CSV and Markdown.
"""
