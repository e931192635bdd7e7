"""What the bias field buys in use (issue 17): on simulated 3-D traffic at 3-12 km with the
package's smooth imposed field, the cross-radar registration error and the absolute error
against ADS-B before and after correcting the plots with the smoothest field (paper 001,
closed form (11)) and with the ADS-B-referenced field, per radar pair / per radar and
overall, in sample (fields and figures on the same plots) and held out (fields from the
even-numbered aircraft, figures on the odd ones); median over seeds.

``python -m solvers_cmp.biasfield_use [--seeds N] [--aircraft N] [--cells K]
[--duration S] [--sigma-adsb M]`` prints one line per seed and the medians (JSON on the
last line).
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from typing import Any

import numpy as np

from optmodels import biasfield as bf
from optmodels.biasfield.referee import adsb_field, compare_fields
from optmodels.scenarios.radar_network import radar_network

__all__ = ["run_seed", "use_figures"]

FIELDS = ("before", "smoothest", "adsb")


def _fields(
    plots: Any,
    radars: Any,
    ref: np.ndarray,
    cells: int,
    sigma: float,
    seed: int,
    adsb: dict[str, str],
) -> dict[str, Any]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # cells without every radar dropped
        fd, _ = bf.build_field_data(plots, radars, cells=cells, seed=seed)
    sol = bf.closed_form(fd)
    af = adsb_field(fd, plots, radars, ref, sigma_reference=sigma, **adsb)
    return {"smoothest": sol.map(), "adsb": af.map(fd)}


def run_seed(
    seed: int,
    *,
    n_aircraft: int = 40,
    duration: float = 1800.0,
    cells: int = 40,
    sigma_adsb: float = 10.0,
    adsb_model: str = "cells",
    adsb_level: str = "discrepancy",
) -> dict[str, Any]:
    """One seed's figures (m): ``in_sample`` and ``held_out``, each {field: {"reg":
    overall, "reg_pairs": {pair: value}, "abs": overall, "abs_radars": {name: value},
    "reg_noise", "abs_noise"}} for ``before``, ``smoothest`` and ``adsb``
    (:func:`~optmodels.biasfield.referee.adsb_field` with ``model=adsb_model``,
    ``level=adsb_level``)."""
    t0 = time.perf_counter()
    sc = radar_network(seed, n_aircraft=n_aircraft, duration=duration, geometry="3d")
    ref = sc.adsb_positions(1000 + seed, sigma=sigma_adsb)
    out: dict[str, Any] = {"seed": seed, "plots": len(sc.plots)}
    train = sc.plots.object % 2 == 0
    for name, fit_rows, eval_rows in (
        ("in_sample", slice(None), slice(None)),
        ("held_out", train, ~train),
    ):
        fit_p = sc.plots.subset(np.arange(len(sc.plots))[fit_rows])
        ev_p = sc.plots.subset(np.arange(len(sc.plots))[eval_rows])
        maps = _fields(
            fit_p,
            sc.radars,
            ref[fit_rows],
            cells,
            sigma_adsb,
            seed,
            {"model": adsb_model, "level": adsb_level},
        )
        cmp_ = compare_fields(ev_p, sc.radars, ref[eval_rows], maps)
        fig: dict[str, Any] = {"plots_compared": cmp_["plots"]}
        for key in FIELDS:
            reg, ab = cmp_[key]["registration"], cmp_[key]["absolute"]
            fig[key] = {
                "reg": reg["overall_m"],
                "reg_noise": reg["noise_m"],
                "reg_pairs": {p: v["rms_m"] for p, v in reg["pairs"].items()},
                "abs": ab["overall_m"],
                "abs_noise": ab["noise_m"],
                "abs_radars": dict(ab["radars_m"]),
            }
        out[name] = fig
    out["seconds"] = time.perf_counter() - t0
    return out


def use_figures(seeds: int = 5, **kw: Any) -> dict[str, Any]:
    """:func:`run_seed` over ``seeds`` seeds, printed, with the medians over seeds of every
    figure and of the after/before ratios."""
    runs = []
    for s in range(seeds):
        r = run_seed(s, **kw)
        runs.append(r)
        for name in ("in_sample", "held_out"):
            f = r[name]
            print(
                f"seed {s} {name:9s} plots {f['plots_compared']:6d}  registration "
                f"{f['before']['reg']:6.0f} -> smoothest {f['smoothest']['reg']:5.1f}, "
                f"ADS-B {f['adsb']['reg']:5.1f} (noise {f['before']['reg_noise']:3.0f})  "
                f"absolute {f['before']['abs']:6.0f} -> smoothest "
                f"{f['smoothest']['abs']:5.1f}, ADS-B {f['adsb']['abs']:5.1f} (noise "
                f"{f['before']['abs_noise']:3.0f})  [{r['seconds']:.1f} s]",
                flush=True,
            )
    med: dict[str, Any] = {}
    for name in ("in_sample", "held_out"):
        m: dict[str, Any] = {}
        for key in FIELDS:
            m[key] = {
                "reg": float(np.nanmedian([r[name][key]["reg"] for r in runs])),
                "abs": float(np.nanmedian([r[name][key]["abs"] for r in runs])),
                "reg_pairs": {
                    p: float(np.nanmedian([r[name][key]["reg_pairs"][p] for r in runs]))
                    for p in runs[0][name][key]["reg_pairs"]
                },
                "abs_radars": {
                    p: float(np.nanmedian([r[name][key]["abs_radars"][p] for r in runs]))
                    for p in runs[0][name][key]["abs_radars"]
                },
            }
            if key != "before":
                m[key]["worst_pair_ratio"] = float(
                    np.nanmedian(
                        [
                            max(
                                r[name][key]["reg_pairs"][p] / v
                                for p, v in r[name]["before"]["reg_pairs"].items()
                            )
                            for r in runs
                        ]
                    )
                )
                m[key]["max_worst_pair_ratio"] = float(
                    max(
                        max(
                            r[name][key]["reg_pairs"][p] / v
                            for p, v in r[name]["before"]["reg_pairs"].items()
                        )
                        for r in runs
                    )
                )
                m[key]["max_abs_ratio"] = float(
                    max(r[name][key]["abs"] / r[name]["before"]["abs"] for r in runs)
                )
                m[key]["max_reg_ratio"] = float(
                    max(r[name][key]["reg"] / r[name]["before"]["reg"] for r in runs)
                )
        m["reg_noise"] = float(np.nanmedian([r[name]["before"]["reg_noise"] for r in runs]))
        m["abs_noise"] = float(np.nanmedian([r[name]["before"]["abs_noise"] for r in runs]))
        med[name] = m
    return {"settings": kw, "seeds": seeds, "runs": runs, "median": med}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--aircraft", type=int, default=40)
    ap.add_argument("--duration", type=float, default=1800.0, help="s")
    ap.add_argument("--cells", type=int, default=40)
    ap.add_argument("--sigma-adsb", type=float, default=10.0, help="m, 1σ per axis")
    ap.add_argument("--adsb-model", default="cells", choices=("cells", "interpolant"))
    ap.add_argument("--adsb-level", default="discrepancy", choices=("discrepancy", "means"))
    a = ap.parse_args()
    res = use_figures(
        a.seeds,
        n_aircraft=a.aircraft,
        duration=a.duration,
        cells=a.cells,
        sigma_adsb=a.sigma_adsb,
        adsb_model=a.adsb_model,
        adsb_level=a.adsb_level,
    )
    print(json.dumps(res["median"]))


if __name__ == "__main__":
    main()
