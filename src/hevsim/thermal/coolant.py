"""Coolant properties (thesis Table 4.4) and a 1-D channel model coupled at the channel wall.

The channel model is quasi-steady per step (the coolant crosses the plate in well under a
second at 10 L/min): along the path the wall is cut into segments; in segment i with wall
temperature T_w,i, area A_i and film h the exact solution of ``m_dot c_p dT/dx = h P (T_w - T)``
gives ``T_out = T_w + (T_in - T_w) exp(-NTU_i)`` with ``NTU_i = h A_i / (m_dot c_p)``, and the
segment-mean fluid temperature ``T_w + (T_in - T_w) (1 - exp(-NTU_i)) / NTU_i`` drives the FEM
wall film. It implements :class:`hevsim.thermal.solver.WallCoolant`, so a 3D fluid model with
the same two methods can replace it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hevsim.errors import ConfigError

#: Laminar fully developed Nusselt number, constant wall temperature (circular duct).
NU_LAMINAR = 3.66
#: Reynolds numbers bounding the laminar-turbulent blend.
RE_LAMINAR_MAX = 2300.0
RE_TURBULENT_MIN = 3000.0


@dataclass(frozen=True)
class Coolant:
    """Incompressible coolant: k [W/(m K)], rho [kg/m^3], mu [Pa s], c_p [J/(kg K)].

    Defaults: 50/50 water-ethylene glycol, thesis Table 4.4 (k, rho, mu). Table 4.4 gives no
    specific heat (Fluid.inp's ``*Specific Heat 50.`` is not physical); 3300 J/(kg K) is the
    handbook value of 50 % ethylene glycol near 15-20 °C (ASHRAE Handbook Fundamentals, ch. 31).
    """

    conductivity_w_mk: float = 0.43
    density_kg_m3: float = 1056.0
    viscosity_pa_s: float = 0.0085
    specific_heat_j_kgk: float = 3300.0

    def check(self, where: str = "coolant") -> Coolant:
        for key in ("conductivity_w_mk", "density_kg_m3", "viscosity_pa_s", "specific_heat_j_kgk"):
            v = getattr(self, key)
            if not (math.isfinite(v) and v > 0.0):
                raise ConfigError(
                    f"{where}: key '{key}' = {v!r} is not physical; expected a finite positive number."
                )
        return self

    @property
    def prandtl(self) -> float:
        return self.viscosity_pa_s * self.specific_heat_j_kgk / self.conductivity_w_mk


#: 50/50 ethylene glycol-water ("MEG 50") vs temperature [°C]: density [kg/m^3], specific heat
#: [J/(kg K)], conductivity [W/(m K)], dynamic viscosity [Pa s]. Source: L. Laloui and
#: A. F. Rotta Loria, *Analysis and Design of Energy Geostructures*, Academic Press (2020),
#: Table 3.8 "Some thermophysical properties of MEG 50". Thesis Table 4.4 gives only constants.
MEG50_TABLE: dict[str, tuple[float, ...]] = {
    "temp_c": (-10.0, -5.0, 0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 40.0),
    "density_kg_m3": (1094.0, 1092.0, 1090.0, 1087.0, 1084.0, 1082.0, 1079.0, 1073.0, 1067.0),
    "specific_heat_j_kgk": (3201.0, 3221.0, 3240.0, 3260.0, 3280.0, 3301.0, 3321.0, 3361.0, 3402.0),
    "conductivity_w_mk": (0.413, 0.412, 0.411, 0.410, 0.408, 0.407, 0.406, 0.403, 0.400),
    "viscosity_pa_s": (
        5.316e-3, 4.428e-3, 3.723e-3, 3.157e-3, 2.700e-3, 2.326e-3, 2.019e-3, 1.552e-3, 1.223e-3
    ),
}  # fmt: skip

#: Names of the coolant property sets accepted by :func:`coolant_properties`.
COOLANT_PROPERTY_SETS = ("table_4_4", "meg50_table")


def meg50_coolant(temp_c: float) -> Coolant:
    """50/50 water-ethylene glycol at ``temp_c`` from :data:`MEG50_TABLE`.

    Linear interpolation in temperature for density, specific heat and conductivity, linear in
    log(viscosity) for the viscosity (Andrade-like); no extrapolation outside -10..40 °C.
    """
    t = MEG50_TABLE["temp_c"]
    if not (math.isfinite(temp_c) and t[0] <= temp_c <= t[-1]):
        raise ConfigError(
            f"coolant: temperature {temp_c!r} °C is outside the MEG 50 table ({t[0]:g} to {t[-1]:g} °C); "
            "use the constant Table 4.4 properties or a temperature inside the table."
        )

    def lin(key: str) -> float:
        return float(np.interp(temp_c, t, MEG50_TABLE[key]))

    mu = float(np.exp(np.interp(temp_c, t, np.log(MEG50_TABLE["viscosity_pa_s"]))))
    return Coolant(lin("conductivity_w_mk"), lin("density_kg_m3"), mu, lin("specific_heat_j_kgk"))


def nusselt(reynolds: float, prandtl: float) -> float:
    """Nusselt number by flow regime: laminar 3.66, Gnielinski above Re 3000, linear blend between."""

    def gnielinski(re: float) -> float:
        f = (0.79 * math.log(re) - 1.64) ** -2
        return (
            (f / 8.0)
            * (re - 1000.0)
            * prandtl
            / (1.0 + 12.7 * math.sqrt(f / 8.0) * (prandtl ** (2 / 3) - 1.0))
        )

    if reynolds <= RE_LAMINAR_MAX:
        return NU_LAMINAR
    if reynolds >= RE_TURBULENT_MIN:
        return max(NU_LAMINAR, gnielinski(reynolds))
    w = (reynolds - RE_LAMINAR_MAX) / (RE_TURBULENT_MIN - RE_LAMINAR_MAX)
    return (1.0 - w) * NU_LAMINAR + w * max(NU_LAMINAR, gnielinski(RE_TURBULENT_MIN))


class ChannelModel:
    """1-D quasi-steady channel: inlet temperature [K], flow [m^3/s], rectangular cross-section [m]."""

    def __init__(
        self,
        n_segments: int,
        *,
        inlet_temp_k: float,
        flow_m3_s: float,
        width_m: float,
        height_m: float,
        coolant: Coolant | None = None,
    ) -> None:
        self.coolant = (coolant or Coolant()).check()
        for key, v in (
            ("inlet_temp_k", inlet_temp_k),
            ("flow_m3_s", flow_m3_s),
            ("width_m", width_m),
            ("height_m", height_m),
        ):
            if not (math.isfinite(v) and v > 0.0):
                raise ConfigError(
                    f"coolant: '{key}' = {v!r} is not physical; expected a finite positive number."
                )
        if n_segments < 1:
            raise ConfigError(f"coolant: n_segments = {n_segments}; expected at least 1.")
        self.n_segments = int(n_segments)
        #: configured channel segment of each segment (when empty ones were dropped)
        self.configured_segments = np.arange(self.n_segments)
        self.inlet_temp_k = float(inlet_temp_k)
        self.flow_m3_s = float(flow_m3_s)
        area = width_m * height_m
        self.hydraulic_diameter_m = 4.0 * area / (2.0 * (width_m + height_m))
        self.velocity_mps = flow_m3_s / area
        c = self.coolant
        self.reynolds = c.density_kg_m3 * self.velocity_mps * self.hydraulic_diameter_m / c.viscosity_pa_s
        self.nusselt = nusselt(self.reynolds, c.prandtl)
        self.h_w_m2k = self.nusselt * c.conductivity_w_mk / self.hydraulic_diameter_m
        self.capacity_rate_w_k = c.density_kg_m3 * flow_m3_s * c.specific_heat_j_kgk
        self.outlet_temp_k = self.inlet_temp_k
        self.heat_w = 0.0

    def heat_transfer_coefficient_w_m2k(self) -> np.ndarray:
        return np.full(self.n_segments, self.h_w_m2k)

    def fluid_temperature_k(self, wall_temp_k: np.ndarray, wall_area_m2: np.ndarray) -> np.ndarray:
        """Segment-mean fluid temperature [K]; also sets ``outlet_temp_k`` and ``heat_w``."""
        ntu = self.h_w_m2k * np.asarray(wall_area_m2, dtype=float) / self.capacity_rate_w_k
        decay = np.exp(-ntu)
        mean_factor = np.where(ntu > 1e-12, (1.0 - decay) / np.where(ntu > 1e-12, ntu, 1.0), 1.0)
        t_in = self.inlet_temp_k
        mean = np.empty(self.n_segments)
        for i, tw in enumerate(np.asarray(wall_temp_k, dtype=float)):
            mean[i] = tw + (t_in - tw) * mean_factor[i]
            t_in = tw + (t_in - tw) * decay[i]
        self.outlet_temp_k = float(t_in)
        self.heat_w = self.capacity_rate_w_k * (self.outlet_temp_k - self.inlet_temp_k)
        return mean

    def fluid_sensitivity(self, wall_area_m2: np.ndarray) -> np.ndarray:
        """``d T_f,i / d T_w,j`` (n_segments, n_segments), lower triangular: the segment-mean fluid
        temperatures of :meth:`fluid_temperature_k` are affine in the wall temperatures, so
        ``T_f(T_w) = T_f(T_w0) + M (T_w - T_w0)`` exactly (the solver's implicit coupling)."""
        ntu = self.h_w_m2k * np.asarray(wall_area_m2, dtype=float) / self.capacity_rate_w_k
        decay = np.exp(-ntu)
        mean_factor = np.where(ntu > 1e-12, (1.0 - decay) / np.where(ntu > 1e-12, ntu, 1.0), 1.0)
        n = self.n_segments
        sens = np.zeros((n, n))
        inlet = np.zeros(n)  # d (inlet of segment i) / d T_w
        for i in range(n):
            sens[i] = mean_factor[i] * inlet
            sens[i, i] += 1.0 - mean_factor[i]
            inlet = decay[i] * inlet
            inlet[i] += 1.0 - decay[i]
        return sens


def segments_along_path(centroids_m: np.ndarray, path_m: np.ndarray, n_segments: int) -> np.ndarray:
    """Segment index of each point: nearest point on the polyline ``path_m``, arc length binned."""
    a, b = path_m[:-1], path_m[1:]
    seg_len = np.linalg.norm(b - a, axis=1)
    s0 = np.concatenate(([0.0], np.cumsum(seg_len)))
    d = b - a
    rel = centroids_m[:, None, :] - a[None]
    u = np.clip(np.einsum("kij,ij->ki", rel, d) / np.maximum(seg_len**2, 1e-300), 0.0, 1.0)
    dist = np.linalg.norm(rel - u[..., None] * d[None], axis=2)
    j = np.argmin(dist, axis=1)
    s = s0[j] + u[np.arange(len(j)), j] * seg_len[j]
    return np.minimum((s / s0[-1] * n_segments).astype(np.int64), n_segments - 1)


class PrescribedWallCoolant:
    """A :class:`hevsim.thermal.solver.WallCoolant` whose film [W/(m^2 K)] and fluid
    temperature [K] per segment are set from outside (a coolant model in another process or
    tool, coupled through the co-simulation master)."""

    def __init__(self, n_segments: int) -> None:
        self.n_segments = int(n_segments)
        self.configured_segments = np.arange(self.n_segments)
        self.h_w_m2k = np.zeros(self.n_segments)
        self.fluid_k = np.zeros(self.n_segments)

    def heat_transfer_coefficient_w_m2k(self) -> np.ndarray:
        return self.h_w_m2k.copy()

    def fluid_temperature_k(self, wall_temp_k: np.ndarray, wall_area_m2: np.ndarray) -> np.ndarray:
        return self.fluid_k.copy()


def channel_segments(
    wall_centroids_m: np.ndarray, path_m: np.ndarray, n_segments: int
) -> tuple[np.ndarray, np.ndarray]:
    """Coolant segment of each wall facet, numbered without gaps, and the configured segment
    (0 .. n_segments-1 along ``path_m``) of each of those: ``(segment_of_facet, configured)``.
    Segments that no facet reaches (coarse meshes) are dropped."""
    seg = segments_along_path(wall_centroids_m, path_m, n_segments)
    used = np.unique(seg)
    return np.searchsorted(used, seg), used
