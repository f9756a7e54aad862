"""grindtwin's mill twin: mineralogy, size grid, breakage, effects, the CasADi mill model, solvers."""

from .errors import ModelError, SolverError, TwinError, TwinInputError
from .mineralogy import Mineralogy, Texture
from .ores import Blend, load_ore, reference_ores

__all__ = ["Blend", "Mineralogy", "ModelError", "SolverError", "Texture", "TwinError",
           "TwinInputError", "load_ore", "reference_ores"]
