"""grindtwin's mill twin: size grid, breakage, the mill, effects, the CasADi mill model and the
``Twin`` facade; subpackages ``twin.ore`` (characterisation), ``twin.solve`` (steady states and
runs), ``twin.calibration`` (breakage maps, DEM chain, table fits, calibration files) and
``twin.surrogate`` (the PLS soft sensor, imported on its own: it needs scikit-learn)."""

from .breakage import BreakageParams, OreBreakage, austin_selection, ore_breakage
from .effects import EFFECTS, Effect, known_effects
from .effects.classification import Hydrocyclone, hydrocyclone_from
from .errors import ModelError, SolverError, TwinError, TwinInputError
from .mill import MILLS, POWER_MODELS, Mill, bond_power_kw, get_mill, hogg_fuerstenau_power_kw, load_status, power_kw
from .model import INPUT_NAMES, Model, ModelSpec
from .ore import Blend, Mineralogy, Texture, load_ore, reference_ores
from .sizes import GatesGaudinSchuhmann, SizeGrid, TabulatedPSD, discretise, pxx_um
from .solve import SteadyState, Trajectory
from .twin import DEFAULT_EFFECTS, Twin
from .sizing import SizedMill, size_mill, write_preset

__all__ = [
    "Blend", "BreakageParams", "DEFAULT_EFFECTS", "EFFECTS", "Effect", "GatesGaudinSchuhmann", "INPUT_NAMES", "MILLS",
    "Mill", "Mineralogy", "POWER_MODELS", "hydrocyclone_from", "TabulatedPSD", "power_kw", "Hydrocyclone", "Model", "ModelError", "ModelSpec", "OreBreakage", "SizeGrid", "SolverError", "SteadyState",
    "SizedMill", "Texture", "Trajectory", "Twin", "size_mill", "write_preset", "TwinError", "TwinInputError", "austin_selection", "bond_power_kw",
    "discretise", "get_mill", "hogg_fuerstenau_power_kw", "known_effects", "load_ore", "load_status", "ore_breakage",
    "pxx_um", "reference_ores",
]
