"""Ore characterisation: minerals and modal mineralogy, the reference ore types and blends,
sample tables, ore typing (PCA + clustering), nano-indentation (Oliver-Pharr) and fracture-energy
distributions. Nothing here knows the mill; the mill model reads an ore's mineralogy only."""

from .fracture_energy import (BreakageOutcomeFit, FractureEnergyFit, SizeDependence, breakage_probability,
                              fit_breakage_outcomes, fit_by_group, fit_fracture_energy, fit_size_dependence,
                              read_single_particle, sample_fracture_energies, validate_single_particle)
from .indentation import (AreaFunction, IndentationResult, Indenter, analyse_curves, oliver_pharr, read_curves,
                          reduced_modulus_gpa, synthesize_curve, youngs_from_reduced_gpa)
from .mineralogy import Mineralogy, Texture
from .minerals import (CLAY_MINERALS, CUSHIONING_MINERALS, MICA_MINERALS, SULFIDE_MINERALS, Mineral,
                       mineral_names, mineral_table, source_table)
from .ores import BLEND_SUM_TOLERANCE, Blend, load_ore, reference_ores
from .oretyping import OreTyper
from .sample_library import generate_library, load_reference_samples
from .samples import (SampleTableError, from_mineralogies, read_samples, to_mineralogies, to_mineralogy,
                      validate_samples)

__all__ = [
    "AreaFunction", "BLEND_SUM_TOLERANCE", "Blend", "BreakageOutcomeFit", "CLAY_MINERALS", "CUSHIONING_MINERALS",
    "FractureEnergyFit", "IndentationResult", "Indenter", "MICA_MINERALS", "Mineral", "Mineralogy", "OreTyper",
    "SULFIDE_MINERALS", "SampleTableError", "SizeDependence", "Texture", "analyse_curves", "breakage_probability",
    "fit_breakage_outcomes", "fit_by_group", "fit_fracture_energy", "fit_size_dependence", "from_mineralogies",
    "generate_library", "load_ore", "load_reference_samples", "mineral_names", "mineral_table", "oliver_pharr",
    "read_curves", "read_samples", "read_single_particle", "reduced_modulus_gpa", "reference_ores",
    "sample_fracture_energies", "source_table", "synthesize_curve", "to_mineralogies", "to_mineralogy",
    "validate_samples", "youngs_from_reduced_gpa",
]
