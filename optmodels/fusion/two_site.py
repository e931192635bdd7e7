"""The two-site passive system of paper 003's introduction: geometry and measurements
(azimuths at A and B, range difference), their Jacobian and noise, the two minimal
estimators (triangulation, azimuth + range difference), their first-order covariances
S1, S2, S12, the CRB, the degenerate-geometry checks, and the fusion (1) of the two
estimators. The joint ML (the original problem) is in
:mod:`optmodels.fusion.two_site_ml`, inherited by :class:`TwoSiteSystem`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from optmodels.core import (
    MAX_MAGNITUDE,
    FloatArray,
    ProblemError,
    as_choice,
    as_count,
    as_finite_array,
    as_flag,
    as_positive,
)
from optmodels.fusion.two_site_ml import JointMLMixin
from optmodels.fusion.weights import _correlated_weight, _weight

#: Reading of the measurement vector z of :class:`TwoSiteSystem`.
MEASUREMENTS = ("azimuth A", "azimuth B", "range difference")


#: Largest condition number of a whitened measurement Jacobian accepted by
#: :meth:`TwoSiteSystem.covariances` and :meth:`TwoSiteSystem.crb`: S = (JᵀR⁻¹J)⁻¹ then
#: has condition ≤ 1e14, the limit :func:`optmodels.core.check_spd` accepts, so the
#: matrices can be fused. For the default system (20 km baseline, 3 mrad, 3 m) the
#: conditions grow ∝ range far away (estimator 2: 2e-3 per metre), so ranges beyond about
#: 5e9 m are refused, besides the line through the sites.
GEOMETRY_COND = 1e7


@dataclass(frozen=True)
class TwoSiteSystem(JointMLMixin):
    r"""The two-position passive system of the paper's introduction.

    Receiving sites A and B on a baseline (positions (2,), metres, East-North); each
    measures the azimuth of the emitter (clockwise from North, :math:`\operatorname{atan2}
    (dx, dy)`), and the pair measures the range difference
    :math:`\Delta r = \|x - B\| - \|x - A\|`. Noise is independent, Gaussian, with standard
    deviations ``sigma_azimuth`` (rad) and ``sigma_range_difference`` (m).

    Two minimal estimators of the position x (the paper's "measurers"):

    * estimator 1, :meth:`triangulate`: the two azimuths;
    * estimator 2, :meth:`azimuth_range_difference`: the azimuth at A and Δr.

    Both use the azimuth at A, so their errors are **correlated**
    (:meth:`covariances` returns S1, S2 and S12 to first order); the paper's fusion (1)
    assumes independent measurers. The original problem, ML from all three measurements,
    is :meth:`joint_ml` (CasADi/IPOPT); its first-order covariance is :meth:`crb`.

    Degenerate geometry: at a site the azimuth is undefined; on the line through the
    sites the two bearings are parallel (estimator 1 is singular everywhere on it), and on
    its extension beyond the sites Δr is constant (±baseline), so estimator 2 and the
    joint Fisher information are singular there too: the position along the line is not
    observed (infinite variance). :meth:`covariances` and :meth:`crb` refuse such
    positions (ProblemError naming the position), judged by the condition number of the
    whitened Jacobian against :data:`GEOMETRY_COND`; ``on_degenerate="nan"`` returns NaN
    matrices there instead (for maps).
    """

    site_a: FloatArray
    site_b: FloatArray
    sigma_azimuth: float
    sigma_range_difference: float

    def __post_init__(self) -> None:
        a = as_finite_array(
            "fusion.TwoSiteSystem site_a", self.site_a, shape=(2,), max_abs=MAX_MAGNITUDE
        )
        b = as_finite_array(
            "fusion.TwoSiteSystem site_b", self.site_b, shape=(2,), max_abs=MAX_MAGNITUDE
        )
        if np.linalg.norm(b - a) == 0:
            raise ProblemError("fusion.TwoSiteSystem site_b: coincides with site_a (zero baseline)")
        for name in ("sigma_azimuth", "sigma_range_difference"):
            v = as_positive(f"fusion.TwoSiteSystem {name}", getattr(self, name))
            object.__setattr__(self, name, v)
        if self.sigma_azimuth > np.pi:
            raise ProblemError(
                f"fusion.TwoSiteSystem sigma_azimuth: {self.sigma_azimuth:g} "
                "rad exceeds π (give radians)"
            )
        object.__setattr__(self, "site_a", a)
        object.__setattr__(self, "site_b", b)

    @classmethod
    def on_baseline(
        cls,
        baseline: float = 20_000.0,
        sigma_azimuth: float = 3e-3,
        sigma_range_difference: float = 3.0,
    ) -> TwoSiteSystem:
        """Sites at (∓baseline/2, 0), metres. Defaults: a 20 km baseline, σ_az = 3 mrad
        (0.17°), σ_Δr = 3 m (10 ns) -- both estimators then matter over the region of the
        demo."""
        b = as_positive("fusion.TwoSiteSystem.on_baseline baseline", baseline)
        if b > MAX_MAGNITUDE:
            raise ProblemError(
                f"fusion.TwoSiteSystem.on_baseline baseline: {b:g} m above "
                f"{MAX_MAGNITUDE:.0e} (change units)"
            )
        h = 0.5 * b
        return cls(np.array([-h, 0.0]), np.array([h, 0.0]), sigma_azimuth, sigma_range_difference)

    @property
    def baseline(self) -> float:
        return float(np.linalg.norm(self.site_b - self.site_a))

    @property
    def noise_cov(self) -> FloatArray:
        """R = diag(σ_az², σ_az², σ_Δr²) of z."""
        return np.diag(
            [self.sigma_azimuth**2, self.sigma_azimuth**2, self.sigma_range_difference**2]
        )

    # ------------------------------------------------------------------ model
    def _pos(self, x: ArrayLike, name: str = "x") -> FloatArray:
        arr = as_finite_array(name, x, max_abs=MAX_MAGNITUDE)
        if arr.shape[-1:] != (2,):
            raise ProblemError(f"{name}: expected positions (..., 2), got shape {arr.shape}")
        return arr

    def _off_sites(self, p: FloatArray, name: str) -> None:
        """Refuse positions at a site (azimuth undefined there)."""
        for label, site in (("A", self.site_a), ("B", self.site_b)):
            at = np.all(p == site, axis=-1)
            if np.any(at):
                idx = _first_index(at)
                raise ProblemError(
                    f"{_at(name, idx)} = {_xy(p[idx])} m coincides with site "
                    f"{label}: the azimuth is undefined there"
                )

    def measure(self, x: ArrayLike) -> FloatArray:
        """Noise-free z(x) = (azimuth A, azimuth B, Δr), (..., 3). ProblemError at a site."""
        p = self._pos(x, "fusion.TwoSiteSystem.measure x")
        self._off_sites(p, "fusion.TwoSiteSystem.measure x")
        return self._measure(p)

    def _measure(self, p: FloatArray) -> FloatArray:
        da, db = p - self.site_a, p - self.site_b
        return np.stack(
            [
                np.arctan2(da[..., 0], da[..., 1]),
                np.arctan2(db[..., 0], db[..., 1]),
                np.hypot(db[..., 0], db[..., 1]) - np.hypot(da[..., 0], da[..., 1]),
            ],
            axis=-1,
        )

    def jacobian(self, x: ArrayLike) -> FloatArray:
        """∂z/∂x, (..., 3, 2). For azimuth atan2(dx, dy): ∂/∂x = (dy, −dx)/ρ².
        ProblemError at a site (it is defined everywhere else, on the baseline too)."""
        p = self._pos(x, "fusion.TwoSiteSystem.jacobian x")
        self._off_sites(p, "fusion.TwoSiteSystem.jacobian x")
        return self._jac(p)

    def _jac(self, p: FloatArray) -> FloatArray:
        """Unchecked Jacobian (NaN at a site)."""
        rows = []
        with np.errstate(divide="ignore", invalid="ignore"):
            for s in (self.site_a, self.site_b):
                d = p - s
                r2 = d[..., 0] ** 2 + d[..., 1] ** 2
                rows.append(np.stack([d[..., 1] / r2, -d[..., 0] / r2], axis=-1))
            ua = (p - self.site_a) / np.linalg.norm(p - self.site_a, axis=-1, keepdims=True)
            ub = (p - self.site_b) / np.linalg.norm(p - self.site_b, axis=-1, keepdims=True)
        rows.append(ub - ua)
        return np.stack(rows, axis=-2)

    def sample(self, x: ArrayLike, trials: int, rng: np.random.Generator) -> FloatArray:
        """Noisy measurements (trials, 3) at one position x (2,); azimuths wrapped."""
        p = as_finite_array("fusion.TwoSiteSystem.sample x", x, shape=(2,), max_abs=MAX_MAGNITUDE)
        self._off_sites(p, "fusion.TwoSiteSystem.sample x")
        k = as_count("fusion.TwoSiteSystem.sample trials", trials, minimum=1)
        if not isinstance(rng, np.random.Generator):
            raise ProblemError(
                "fusion.TwoSiteSystem.sample rng: expected a "
                f"numpy.random.Generator, got {type(rng).__name__}"
            )
        z = self._measure(p) + rng.normal(size=(k, 3)) * np.sqrt(np.diag(self.noise_cov))
        z[:, :2] = np.angle(np.exp(1j * z[:, :2]))
        return z

    # ------------------------------------------------------------------ geometry
    @property
    def _harmless(self) -> FloatArray:
        """A regular position (one baseline from A, perpendicular to AB) that stands in
        for degenerate ones before their results are set to NaN."""
        d = self.site_b - self.site_a
        return self.site_a + np.array([-d[1], d[0]])

    def _conditions(self, p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Condition numbers (...,) of the whitened Jacobians of estimator 1 (azimuths A,
        B), estimator 2 (azimuth A, Δr) and the joint problem (all three); inf at a site
        or where the Jacobian is singular."""
        jw = self._jac(p) / np.sqrt(np.diag(self.noise_cov))[:, None]
        out = []
        for rows in ([0, 1], [0, 2], [0, 1, 2]):
            sub = jw[..., rows, :]
            good = np.all(np.isfinite(sub), axis=(-2, -1))
            sv = np.linalg.svd(np.where(good[..., None, None], sub, 0.0), compute_uv=False)
            with np.errstate(divide="ignore", invalid="ignore"):
                cond = sv[..., 0] / sv[..., -1]
            out.append(np.where(good & np.isfinite(cond), cond, np.inf))
        return out[0], out[1], out[2]

    def _refuse_degenerate(
        self, p: FloatArray, bad: np.ndarray, cond: FloatArray, name: str, what: str
    ) -> None:
        if np.any(bad):
            idx = _first_index(bad)
            self._off_sites(p, name)
            raise ProblemError(
                f"{_at(name, idx)} = {_xy(p[idx])} m: degenerate geometry for {what} (condition "
                f"number {float(cond[idx]):.2g} of its whitened Jacobian, limit "
                f"{GEOMETRY_COND:.0e}): on or near the line through the sites, where the "
                "position along that line is not observed, or too far away; give "
                "on_degenerate='nan' for NaN there instead"
            )

    def covariances(
        self, x: ArrayLike, *, on_degenerate: Literal["raise", "nan"] = "raise"
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """First-order S1, S2 and S12 = Cov(a1, a2) at position(s) x, each (..., 2, 2), m².

        a_k = x + G_k e_k with G_k = (∂z_k/∂x)⁻¹; e_1 = (e_azA, e_azB), e_2 = (e_azA, e_Δr),
        so S12 = G_1 Cov(e_1, e_2) G_2ᵀ with Cov(e_1, e_2) = diag(σ_az², 0).

        Raises ProblemError naming the first position where estimator 1 or 2 is degenerate
        (a site; the line through the sites for estimator 1, its extension beyond the
        sites for estimator 2; condition number of the whitened Jacobian above
        :data:`GEOMETRY_COND`, so that S_k stays within what :func:`weight_matrix`
        accepts). With ``on_degenerate="nan"`` those matrices are NaN instead (S12 NaN
        where either is).
        """
        name = "fusion.TwoSiteSystem.covariances x"
        mode = as_choice(
            "fusion.TwoSiteSystem.covariances on_degenerate", on_degenerate, ("raise", "nan")
        )
        p = self._pos(x, name)
        c1, c2, _ = self._conditions(p)
        bad1, bad2 = ~(c1 <= GEOMETRY_COND), ~(c2 <= GEOMETRY_COND)
        if mode == "raise":
            self._refuse_degenerate(p, bad1, c1, name, "estimator 1 (azimuths A and B)")
            self._refuse_degenerate(p, bad2, c2, name, "estimator 2 (azimuth A and Δr)")
        # degenerate positions are replaced by a harmless point, then set to NaN
        q = np.where((bad1 | bad2)[..., None], self._harmless, p)
        j = self._jac(q)
        g1 = np.linalg.inv(j[..., [0, 1], :])
        g2 = np.linalg.inv(j[..., [0, 2], :])
        r = self.noise_cov
        r1, r2 = r[np.ix_([0, 1], [0, 1])], r[np.ix_([0, 2], [0, 2])]
        r12 = np.diag([self.sigma_azimuth**2, 0.0])
        tr = np.swapaxes
        s1 = g1 @ r1 @ tr(g1, -1, -2)
        s2 = g2 @ r2 @ tr(g2, -1, -2)
        s12 = g1 @ r12 @ tr(g2, -1, -2)
        nan = np.full((2, 2), np.nan)
        s1 = np.where(bad1[..., None, None], nan, s1)
        s2 = np.where(bad2[..., None, None], nan, s2)
        s12 = np.where((bad1 | bad2)[..., None, None], nan, s12)
        return s1, s2, np.asarray(s12, dtype=float)

    def crb(self, x: ArrayLike, *, on_degenerate: Literal["raise", "nan"] = "raise") -> FloatArray:
        """(Jᵀ R⁻¹ J)⁻¹, (..., 2, 2), m²: first-order covariance of the joint ML (the CRB).

        On the extension of the baseline beyond the sites (and at the sites) the Fisher
        information JᵀR⁻¹J is singular: the bound on the position along the line is
        infinite. Such positions (condition number of the whitened Jacobian above
        :data:`GEOMETRY_COND`) raise ProblemError naming the position, or give NaN with
        ``on_degenerate="nan"``. Between the sites the joint problem is regular (Δr fixes
        the position along the baseline).
        """
        name = "fusion.TwoSiteSystem.crb x"
        mode = as_choice("fusion.TwoSiteSystem.crb on_degenerate", on_degenerate, ("raise", "nan"))
        p = self._pos(x, name)
        _, _, c = self._conditions(p)
        bad = ~(c <= GEOMETRY_COND)
        if mode == "raise":
            self._refuse_degenerate(p, bad, c, name, "the joint ML (all three measurements)")
        q = np.where(bad[..., None], self._harmless, p)
        out = self._crb(q)
        return np.where(bad[..., None, None], np.full((2, 2), np.nan), out)

    def _crb(self, p: FloatArray) -> FloatArray:
        """Unchecked CRB: the closed-form 2×2 inverse (inf/NaN where singular)."""
        j = self._jac(p)
        info = np.swapaxes(j, -1, -2) @ np.linalg.inv(self.noise_cov) @ j
        a, b, d = info[..., 0, 0], info[..., 0, 1], info[..., 1, 1]
        with np.errstate(divide="ignore", invalid="ignore"):
            det = a * d - b * b
            out = (
                np.stack([np.stack([d, -b], axis=-1), np.stack([-b, a], axis=-1)], axis=-2)
                / det[..., None, None]
            )
        return out

    def residuals(self, z: ArrayLike, x: ArrayLike) -> FloatArray:
        """Whitened residuals R^{-1/2}(z − z(x)), azimuth differences wrapped, (..., 3)."""
        p = self._pos(x, "fusion.TwoSiteSystem.residuals x")
        self._off_sites(p, "fusion.TwoSiteSystem.residuals x")
        return self._residuals(self._z(z), p)

    def _residuals(self, z: FloatArray, p: FloatArray) -> FloatArray:
        d = z - self._measure(p)
        d[..., :2] = np.angle(np.exp(1j * d[..., :2]))
        return d / np.sqrt(np.diag(self.noise_cov))

    # ------------------------------------------------------------------ estimators
    def _z(self, z: ArrayLike, name: str = "z") -> FloatArray:
        arr = as_finite_array(name, z, max_abs=MAX_MAGNITUDE)
        if arr.shape[-1:] != (3,):
            raise ProblemError(
                f"{name}: expected measurements (..., 3) = {MEASUREMENTS}, got shape {arr.shape}"
            )
        return arr

    def triangulate(self, z: ArrayLike) -> FloatArray:
        """Estimator 1: intersection of the two bearings, (..., 2). NaN where the bearings
        do not intersect in front of both sites (target on the baseline's line)."""
        zz = self._z(z)
        ua = np.stack([np.sin(zz[..., 0]), np.cos(zz[..., 0])], axis=-1)
        ub = np.stack([np.sin(zz[..., 1]), np.cos(zz[..., 1])], axis=-1)
        d = self.site_b - self.site_a
        # r_a ua − r_b ub = B − A  (Cramer's rule)
        det = -ua[..., 0] * ub[..., 1] + ua[..., 1] * ub[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            ra = (-d[0] * ub[..., 1] + d[1] * ub[..., 0]) / det
            rb = (ua[..., 0] * d[1] - ua[..., 1] * d[0]) / det
        x = self.site_a + ra[..., None] * ua
        bad = ~((ra > 0) & (rb > 0) & np.isfinite(ra))
        return np.where(bad[..., None], np.nan, x)

    def azimuth_range_difference(self, z: ArrayLike) -> FloatArray:
        """Estimator 2: the bearing from A cut by the hyperbola Δr, (..., 2).

        With ρ = ‖x − A‖ along the bearing u_A: ‖A − B + ρu_A‖ = ρ + Δr gives
        ρ = (Δr² − ‖A − B‖²) / (2(u_A·(A − B) − Δr)); NaN where ρ ≤ 0 (no intersection).
        """
        zz = self._z(z)
        ua = np.stack([np.sin(zz[..., 0]), np.cos(zz[..., 0])], axis=-1)
        ab = self.site_a - self.site_b
        dr = zz[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            rho = (dr**2 - ab @ ab) / (2.0 * (ua @ ab - dr))
        x = self.site_a + rho[..., None] * ua
        return np.where((rho > 0)[..., None] & np.isfinite(rho)[..., None], x, np.nan)

    # ------------------------------------------------------------------ joint ML
    # joint_ml (the original problem) and its Gauss-Newton cross-check are inherited
    # from optmodels.fusion.two_site_ml.JointMLMixin

    def fused(
        self,
        z: ArrayLike,
        w: ArrayLike | None = None,
        *,
        weights_at: Literal["true", "estimated"] = "estimated",
        x_true: ArrayLike | None = None,
        correlated: bool = False,
    ) -> FloatArray:
        """Fusion (1) of the two estimators for every row of z, (T, 2).

        ``w`` (2, 2) fixes the weight (e.g. Ŵ from snapshots); otherwise W is computed from
        the first-order covariances at ``x_true`` (``weights_at="true"``; ProblemError if
        that position is degenerate, see :meth:`covariances`) or at the triangulated
        position of each row (``"estimated"``), independent (2) or, with ``correlated``,
        the correlated fusion of :func:`weight_matrix_correlated`. Rows whose estimators
        do not intersect, or whose estimated position is degenerate, are NaN (as in
        :meth:`triangulate`).
        """
        fn = "fusion.TwoSiteSystem.fused"
        zz = np.atleast_2d(self._z(z, f"{fn} z"))
        weights_at = as_choice(  # type: ignore[assignment]
            f"{fn} weights_at", weights_at, ("true", "estimated")
        )
        as_flag(f"{fn} correlated", correlated)
        a1, a2 = self.triangulate(zz), self.azimuth_range_difference(zz)
        if w is not None:
            wm = as_finite_array(f"{fn} w", w, shape=(2, 2), max_abs=MAX_MAGNITUDE)
            return a1 + (a2 - a1) @ wm.T
        if weights_at == "true":
            if x_true is None:
                raise ProblemError(f"{fn} x_true: needed with weights_at='true'")
            xt = as_finite_array(f"{fn} x_true", x_true, shape=(2,), max_abs=MAX_MAGNITUDE)
            self.covariances(xt)  # refuses a degenerate x_true, naming it
            at = np.broadcast_to(xt, a1.shape)
        else:
            at = a1
        out = np.full_like(a1, np.nan)
        ok = np.all(np.isfinite(a1) & np.isfinite(a2), axis=1)
        s1, s2, s12 = self.covariances(
            np.where(ok[:, None], at, self._harmless), on_degenerate="nan"
        )
        ok &= np.all(np.isfinite(s1) & np.isfinite(s2), axis=(1, 2))
        s1, s2, s12 = s1[ok], s2[ok], s12[ok]
        if correlated:
            wts = _correlated_weight(s1, s12, s1 + s2 - s12 - np.swapaxes(s12, -1, -2))
        else:
            wts = _weight(s1, s2)
        out[ok] = a1[ok] + np.einsum("tij,tj->ti", wts, a2[ok] - a1[ok])
        return out


def _first_index(mask: FloatArray) -> tuple[int, ...]:
    """Index of the first True entry of ``mask`` (() for a scalar mask)."""
    if np.ndim(mask) == 0:
        return ()
    return tuple(int(i) for i in np.argwhere(mask)[0])


def _at(name: str, idx: tuple[int, ...]) -> str:
    """'x' for a single position, 'x[3]' / 'x[1, 2]' for one of many."""
    return f"{name}[{', '.join(map(str, idx))}]" if idx else name


def _xy(p: FloatArray) -> str:
    return f"({float(p[0]):.6g}, {float(p[1]):.6g})"
