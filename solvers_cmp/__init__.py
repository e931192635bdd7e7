"""Solver and formulation comparisons against the papers' closed forms.

Each registered problem contributes one face file ``solvers_cmp/<problem>.py``: its
``--details`` rows and benchmarks, its harness ``Adapter`` and its report section
``write_report`` (both found by the problem's name, no list).
:mod:`solvers_cmp.cases` holds the adapter base class and the registry of adapters,
:mod:`solvers_cmp.report` the shared writers and the harness report,
:mod:`solvers_cmp.harness` the sweep, :mod:`solvers_cmp.common` the timing helpers and
``cpu_name``.
"""
