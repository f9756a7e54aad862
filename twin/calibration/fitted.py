"""The numbers the DEM chain fits to MISSION.md's table, each ore-independent (a property of
the mill, its charge or its slurry), with why it cannot be derived here; the ``table``
calibration (twin.calibration.table) gives the same reasons for the numbers it shares."""

from ..effects.rheology import CLAY_CROWDING_MAX

#: A fitted value within this share of its range's width (in the space the fit searched) of a
#: bound is on it: the bound is then the number used, not one the data determine.
AT_BOUND_RTOL = 1e-6


def on_bound(value: float, lo: float, hi: float) -> bool:
    """Whether a fitted ``value`` in [lo, hi] is on a bound (:data:`AT_BOUND_RTOL`)."""
    return min(value - lo, hi - value) < AT_BOUND_RTOL * (hi - lo)


_WHY_GRATE = ("the lab mill's grate and discharge geometry is not given (MISSION.md gives the mill's size and "
              "speed only), and the DEM drum has no grate")
#: The DEM chain's table step: the only numbers fitted to the table, each ore-independent (a
#: property of the mill, its charge or its slurry), with why it is not derivable here. Start
#: values are only starting points; bounds are physical ranges.
DEM_FITTED = {
    "dem_capture_scale": {"start": 0.02, "bounds": (1e-4, 1e4), "why": (
        "the fraction of a ball pair's geometrically captured bed (r_c = sqrt(R d), one particle layer) that is "
        "nipped and stressed: the drum DEM has balls only, no powder bed, so it gives collision energies and "
        "rates but not how much of the bed a collision stresses (fitted in the UFRJ model too, Tavares & de "
        "Carvalho 2009); one number for every ore")},
    "cushioning_rate_coeff": {"start": 0.4, "bounds": (1e-6, 20.0), "why": (
        "how much clay and mica in the charge slow breakage (twin.effects.cushioning): the DEM particles are "
        "single-phase agglomerates in a dry ball charge, with no soft platy phase in the bed")},
    "slurry_power_coeff": {"start": 0.003, "bounds": (1e-6, 20.0), "why": (
        "how much a clay-thickened slurry lowers the power draw (twin.effects.rheology): the drum DEM is dry "
        "balls without slurry, and no power-viscosity law of the charge is published in closed form")},
    "clay_crowding_coeff": {"start": 0.8, "bounds": (1e-6, CLAY_CROWDING_MAX), "why": (
        "the effective volume of clay platelets in the mill slurry (twin.effects.rheology): no slurry "
        "rheology data; at most the crowding that brings the deposit's clay-richest slurry (40 % clay) to "
        "jamming (twin.effects.rheology.CLAY_CROWDING_MAX)")},
    "lab_power_factor": {"start": 1.3, "bounds": (0.3, 3.0), "why": (
        "Bond's power equation's correction at 0.5 m: the drum DEM's net power is that of the balls alone, "
        "which the table's power (throughput x specific energy) exceeds with powder and slurry in the charge")},
    "lab_grate_d50_um": {"start": 450.0, "bounds": (10.0, 3000.0), "why": _WHY_GRATE},
    "lab_grate_sharpness": {"start": 6.5, "bounds": (0.5, 10.0), "why": _WHY_GRATE},
    "lab_discharge_factor": {"start": 1.25, "bounds": (0.5, 50.0), "why": (
        "the mill's discharge capacity at nominal hold-up (twin.effects.holdup; a volume flow, stated for a "
        "quartz slurry, twin.mill.Mill.free_discharge_tph): set by the discharge geometry and slurry level, "
        "not given")},
}
DEM_NAMES = tuple(DEM_FITTED)
DEM_BOUNDS = {n: v["bounds"] for n, v in DEM_FITTED.items()}
