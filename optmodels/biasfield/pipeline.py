r"""The one owner of the plots → :class:`~optmodels.biasfield.data.FieldData` chain
(paper 001: the track fits (3), the cells and the averaging (6)-(7), the sets (10)).

:func:`field_data_from_plots` runs, in order: the 3-D placement check (plots a 3-D radar
set cannot place are removed and counted), the optional cleaning
(:func:`~optmodels.biasfield.cleaning.clean_plots`), the plots' positions on the common
plane (once, handed to the fits), and :func:`~optmodels.biasfield.cells.build_field_data`
(fits, samples, centres, subsets, averaging, neighbours). The CLI's ``biasfield build``,
the demo and the benchmarks call it instead of assembling the chain by hand.

``coverage="union"`` (the default here) builds the field over the union of coverage: a
cell wherever two radars or more see the traffic, with its own radar subset
(docs/formulations.md, "The field over the union of coverage"); ``"all"`` is the paper's
all-radar averaging.
"""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from optmodels.biasfield.cells import Diagnostics, build_field_data, check_build_arguments
from optmodels.biasfield.data import FieldData
from optmodels.biasfield.tables import PlotTable, RadarSet
from optmodels.core import ProblemError, as_flag, as_instance

__all__ = ["FieldBuild", "field_data_from_plots", "field_data_names", "save_field_data"]


@dataclass
class FieldBuild:
    """What :func:`field_data_from_plots` made: ``data`` (the FieldData), ``diagnostics``
    (:class:`~optmodels.biasfield.cells.Diagnostics`: fits, per-cell counts, stage
    seconds), ``plots`` (the plots the fits used, after placement and cleaning),
    ``dropped`` (plots dropped by reason, every stage), ``cleaning`` (the cleaning's
    :class:`~optmodels.biasfield.cleaning.CleaningReport`, None without cleaning),
    ``warnings`` (the messages of the build, e.g. cells dropped for lack of data) and
    ``timings`` (seconds per stage: ``locate``, ``clean``, ``positions``,
    ``field_data``)."""

    data: FieldData
    diagnostics: Diagnostics
    plots: PlotTable
    dropped: dict[str, int] = field(default_factory=dict)
    cleaning: Any = None
    warnings: list[str] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)


def _say(progress: bool, text: str) -> None:
    """One progress line on stderr (when ``progress`` and stderr is a terminal)."""
    if progress and sys.stderr.isatty():
        print(text, file=sys.stderr, flush=True)


def field_data_from_plots(
    plots: PlotTable,
    radars: RadarSet,
    *,
    cells: int | ArrayLike = 50,
    knot_spacing: float = 20.0,
    coverage: Literal["all", "union"] = "union",
    clean: bool = False,
    locate: bool = True,
    scheduler: Any = None,
    progress: bool = False,
    seed: int = 0,
    **options: Any,
) -> FieldBuild:
    """Plots → FieldData, the whole chain in one place (module docstring).

    Parameters
    ----------
    plots, radars : PlotTable, RadarSet
        The plots (SI: range m, azimuth rad clockwise from each radar's north; heights m
        above WGS-84 in 3-D) and their radars.
    cells : int or (K, 2) array
        A number of k-means centres (placed on the traffic two radars or more share, or
        every radar with ``coverage="all"``) or the centres (m, common plane).
    knot_spacing : float
        Polyline knots of the track fits (3), s (also the longest silence inside one
        track piece: it must exceed the radars' scan intervals).
    coverage : ``"union"`` or ``"all"``
        The field over the union of coverage (per-cell subsets, ``FieldData.seen``) or
        paper 001's all-radar cells.
    clean : bool
        Run :func:`~optmodels.biasfield.cleaning.clean_plots` first (its default limits).
    locate : bool
        Remove (and count) the plots a 3-D radar set cannot place (no height, slant range
        below the height difference).
    scheduler : None, ``"serial"``, ``"processes"``, ``"dask"``, a Dask Client or address
        Where the track fits run (:func:`~optmodels.biasfield.tracks.fit_tracks`).
    progress : bool
        Stage lines and tqdm bars on stderr (only when stderr is a terminal).
    seed : int
        Seed of the k-means start.
    **options
        Passed to :func:`~optmodels.biasfield.cells.build_field_data` (``cell_radius``,
        ``sample_step``, ``neighbour_method``, ``P``, ``exclude_radius``,
        ``subset_share``, ...).
    """
    fn = "biasfield.field_data_from_plots"
    plots = as_instance(f"{fn} plots", plots, PlotTable)
    radars = as_instance(f"{fn} radars", radars, RadarSet)
    clean = as_flag(f"{fn} clean", clean)
    locate = as_flag(f"{fn} locate", locate)
    from optmodels.execution import as_scheduler

    scheduler = as_scheduler(f"{fn} scheduler", scheduler, default="serial")
    if "positions" in options:
        raise ProblemError(f"{fn} positions: computed here (after the placement and cleaning)")
    # every argument of the build checked before the placement, cleaning and positions
    check_build_arguments(
        fn,
        plots,
        radars,
        cells=cells,
        knot_spacing=knot_spacing,
        coverage=coverage,
        seed=seed,
        progress=progress,
        **options,
    )
    timings: dict[str, float] = {}
    dropped: dict[str, int] = {}
    clock = time.perf_counter()
    if locate and radars.is_3d:
        ok = plots.locatable(radars)
        if not ok.all():
            dropped["no height or slant range below height"] = int(np.sum(~ok))
            plots = plots.subset(ok)
    timings["locate"] = time.perf_counter() - clock
    cleaning = None
    if clean:
        from optmodels.biasfield.cleaning import clean_plots

        _say(progress, f"cleaning {len(plots)} plots ...")
        clock = time.perf_counter()
        plots, cleaning = clean_plots(plots, radars)
        for k, v in cleaning.counts.items():
            dropped[k] = dropped.get(k, 0) + int(v)
        timings["clean"] = time.perf_counter() - clock
    _say(progress, f"placing {len(plots)} plots on the common plane ...")
    clock = time.perf_counter()
    if len(plots) == 0:
        raise ProblemError(f"{fn} plots: no plot left to fit (dropped: {dropped or 'none'})")
    z = plots.cartesian(radars)
    timings["positions"] = time.perf_counter() - clock
    _say(progress, "track fits, cells and averaging ...")
    clock = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fd, diag = build_field_data(
            plots,
            radars,
            cells=cells,
            knot_spacing=knot_spacing,
            coverage=coverage,
            scheduler=scheduler,
            positions=z,
            seed=seed,
            progress=progress,
            **options,
        )
    timings["field_data"] = time.perf_counter() - clock
    for reason, n in diag.dropped_plots.items():
        dropped[reason] = dropped.get(reason, 0) + int(n)
    return FieldBuild(fd, diag, plots, dropped, cleaning, [str(w.message) for w in caught], timings)


def save_field_data(
    data: FieldData,
    path: Any,
    *,
    names: tuple[str, ...] | list[str] = (),
    name: str = "biasfield.save_field_data path",
) -> Any:
    """Write ``data`` to the ``.npz`` :meth:`FieldData.load
    <optmodels.biasfield.data.FieldData.load>` reads (the keys of ``FieldData.save``),
    with the radars' ``names`` if given, exactly at ``path`` and atomically
    (:func:`optmodels.io.save_npz`: a kill part-way leaves the previous file readable).
    Returns the path written."""
    from optmodels.io import save_npz

    data = as_instance("biasfield.save_field_data data", data, FieldData)
    if isinstance(names, str | bytes) or not isinstance(names, list | tuple | np.ndarray):
        raise ProblemError(
            f"biasfield.save_field_data names: expected a list of {data.m} radar names, "
            f"got {type(names).__name__} {names!r:.60}"
        )
    if not all(isinstance(v, str) for v in names):
        raise ProblemError(
            f"biasfield.save_field_data names: expected text names, got {names!r:.60}"
        )
    arrays = data.npz_arrays()
    names = tuple(names)
    if names:
        if len(names) != data.m:
            raise ProblemError(
                f"biasfield.save_field_data names: {len(names)} names for {data.m} radars"
            )
        arrays["names"] = np.array(names, dtype=str)
    return save_npz(path, name=name, **arrays)


def field_data_names(path: Any) -> tuple[str, ...]:
    """The radar names a FieldData ``.npz`` carries (written by :func:`save_field_data`,
    e.g. by ``optmodels biasfield build``); ``()`` for a file without them."""
    from optmodels.io import read_npz

    d = read_npz(path, what="FieldData .npz", required=("radars",))
    return tuple(str(v) for v in d["names"]) if "names" in d else ()
