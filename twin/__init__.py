"""grindtwin's mill twin: mineralogy, size grid, breakage, effects, the CasADi mill model,
solvers, calibration, and the characterisation end (samples, ore typing, indentation,
fracture energy)."""

from .errors import ModelError, SolverError, TwinError, TwinInputError
from .fracture_energy import (breakage_probability, fit_breakage_outcomes, fit_by_group, fit_fracture_energy,
                              fit_size_dependence)
from .indentation import AreaFunction, Indenter, oliver_pharr, synthesize_curve
from .mill import MILLS, Mill
from .mineralogy import Mineralogy, Texture
from .ores import Blend, load_ore, reference_ores
from .oretyping import OreTyper
from .sample_library import generate_library, load_reference_samples
from .samples import SampleTableError, read_samples, validate_samples
from .sizes import SizeGrid, pxx_um
from .twin import DEFAULT_EFFECTS, Twin

__all__ = [
    "AreaFunction", "Blend", "DEFAULT_EFFECTS", "Indenter", "MILLS", "Mill", "Mineralogy", "ModelError",
    "OreTyper", "SampleTableError", "SizeGrid", "SolverError", "Texture", "Twin", "TwinError", "TwinInputError",
    "breakage_probability", "fit_breakage_outcomes", "fit_by_group", "fit_fracture_energy", "fit_size_dependence",
    "generate_library", "load_ore", "load_reference_samples", "oliver_pharr", "pxx_um", "read_samples",
    "reference_ores", "synthesize_curve", "validate_samples",
]
