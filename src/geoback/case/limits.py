"""What each kind of quantity may be (refused outside) and usually is (a warning outside).

Plain data with no imports, so that the case checks, the ground and the extension table share
one statement of the ranges."""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Limits:
    """What a quantity may be: values outside [lo, hi] are refused (not physical, or beyond what the
    numerics can honour); outside `plausible` they are unusual for ground and said so."""

    lo: float
    hi: float
    plausible: tuple[float, float]
    usual_for: str = "ground"  # what `plausible` is usual for, in the words of a warning
    natural_lo: bool = False  # lo is a state the thing can be in (a prop without preload), not only the edge of
    # what is physical: an estimate there, or a 95 % interval reaching it, is a finding (the readings bound it
    # on the other side), not a failure of the readings to bound it

    def contains(self, v: float) -> bool:
        return self.lo <= v <= self.hi

    @property
    def ratio_scale(self) -> bool:
        """Positive by nature with no natural zero (a modulus, K0, not a preload): a relative error means
        something, and an interval is kept above 0 by taking it in ln p."""
        return self.lo >= 0 and not self.natural_lo

    def natural(self, bound: float) -> bool:
        """Whether a lower bound at `bound` is this quantity's natural lower limit (``natural_lo``): a fit
        may end there, and an interval reach it, as a finding."""
        return self.natural_lo and bound <= self.lo


def natural_limit(lim: Limits | None, bound: float) -> bool:
    """``Limits.natural`` for a quantity that may have no limits (None: never)."""
    return lim is not None and lim.natural(bound)


MODULUS = Limits(1e-3, 1e9, (500.0, 2e7))  # kPa: 1 Pa .. 1000 GPa allowed; 0.5 MPa .. 20 GPa usual
POISSON = Limits(0.0, 0.4999, (0.05, 0.4995))
EARTH_PRESSURE = Limits(1e-3, 10.0, (0.25, 3.0))
CONSTANT_LENGTH = Limits(-10.0, 10.0, (-0.5, 0.5))  # m: an instrument's reference end moved
CONSTANT_ANGLE = Limits(-1.0, 1.0, (-0.05, 0.05))  # rad: a deflectometer's reference end rotated
BIAS_SHIFT = Limits(-0.05, 0.05, (-2e-3, 2e-3))  # rad: an inclinometer's constant slope offset per reading
DEPTH_OFFSET = Limits(-3.0, 3.0, (-0.5, 0.5))  # m: an inclinometer probe's depth positions shifted
# Mohr-Coulomb strength (kPa, degrees): refused outside [lo, hi], unusual for ground outside `plausible`
COHESION = Limits(0.0, 1e6, (0.0, 500.0))
FRICTION = Limits(0.01, 69.99, (15.0, 45.0))  # the schema takes 0 < phi < 70
DILATION = Limits(0.0, 69.99, (0.0, 20.0))  # and psi <= phi (strength.py)
TENSION = Limits(0.0, 1e6, (0.0, 500.0))
UNIT_WEIGHT = Limits(0.1, 100.0, (12.0, 27.0))  # kN/m3: of soil and rock
RELEASE = Limits(1e-3, 1.0, (0.05, 1.0))  # a fraction of the in-situ wall stress released (beta): at most all of it
# A lining is concrete or shotcrete, not ground: its modulus is usually 1 GPa (shotcrete a few hours
# old, or a segmental ring's joints smeared) to 50 GPa (high-strength concrete). The ground's usual
# range (0.5 MPa .. 20 GPa) let a lining's `E: 30` (30 kPa for 30 GPa) warn as "unusual for ground" and
# `E: 30000` or `E: 30 MPa` (30 MPa where 30 GPa was meant: a thousand times too soft) pass silently.
LINING_MODULUS = Limits(MODULUS.lo, MODULUS.hi, (1e6, 5e7), "a concrete or shotcrete lining")
LINING_POISSON = Limits(POISSON.lo, POISSON.hi, POISSON.plausible, "a concrete or shotcrete lining")

# The unit and range of every named quantity of a case, by its stem (E[clay], E[shotcrete], c[marl],
# beta[advance], ...): the ground's and the lining's elasticity, the in-situ stress ratio, the strength
# of mohr-coulomb layers and the release of the stages (and of the extension 'beta'). The ground, the
# strength and the construction plan answer for their names from this one table.
QUANTITIES: dict[str, tuple[str, Limits]] = {
    "E": ("kPa", MODULUS), "nu": ("-", POISSON), "K0": ("-", EARTH_PRESSURE),
    "c": ("kPa", COHESION), "phi": ("deg", FRICTION), "psi": ("deg", DILATION), "tension": ("kPa", TENSION),
    "beta": ("-", RELEASE), "gamma": ("kN/m3", UNIT_WEIGHT),
}
# The lining's own values (E[shotcrete], nu[shotcrete]): the same units, a lining's usual ranges
LINING: dict[str, tuple[str, Limits]] = {"E": ("kPa", LINING_MODULUS), "nu": ("-", LINING_POISSON)}

# Retaining structures (case/supports.py): a wall is concrete or steel (1 GPa .. 250 GPa usual); a prop's
# or an anchor's axial stiffness per metre run k [kN/m per m] and its preload (lock-off) per metre run
# [kN/m]. A stiffness under 100 kN/m/m or over 1e8 is unusual for a structural support (a unit slip).
WALL_MODULUS = Limits(MODULUS.lo, MODULUS.hi, (1e6, 2.5e8), "a concrete or steel wall")
WALL_POISSON = Limits(POISSON.lo, POISSON.hi, POISSON.plausible, "a concrete or steel wall")
SUPPORT_STIFFNESS = Limits(1e-6, 1e12, (1e2, 1e8), "a prop or anchor")
PRELOAD = Limits(0.0, 1e6, (0.0, 5e3), "a prop or anchor", natural_lo=True)  # 0: the preload lost
WALL: dict[str, tuple[str, Limits]] = {"E": ("kPa", WALL_MODULUS), "nu": ("-", WALL_POISSON)}
SUPPORT: dict[str, tuple[str, Limits]] = {"k": ("kN/m/m", SUPPORT_STIFFNESS), "preload": ("kN/m", PRELOAD)}
