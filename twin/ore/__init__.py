"""Ore characterisation: minerals and modal mineralogy, the reference ore types and blends,
sample tables, ore typing (PCA + clustering), nano-indentation (Oliver-Pharr) and fracture-energy
distributions. Nothing here knows the mill; the mill model reads an ore's mineralogy only."""

from .._lazy import lazy_face

#: Public name -> the module that defines it, imported on first use (PEP 562).
_API = {
    "BreakageOutcomeFit": ".fracture_energy", "FractureEnergyFit": ".fracture_energy",
    "SizeDependence": ".fracture_energy", "breakage_probability": ".fracture_energy",
    "fit_breakage_outcomes": ".fracture_energy", "fit_by_group": ".fracture_energy",
    "fit_fracture_energy": ".fracture_energy", "fit_size_dependence": ".fracture_energy",
    "read_single_particle": ".fracture_energy", "sample_fracture_energies": ".fracture_energy",
    "validate_single_particle": ".fracture_energy",
    "FRACTURE_ENERGY_RANGE_J_KG": ".fracture_energy", "PARTICLE_SIZE_RANGE_MM": ".fracture_energy",
    "HARDNESS_RANGE_GPA": ".indentation", "INDENTER_YOUNGS_RANGE_GPA": ".indentation",
    "REDUCED_MODULUS_RANGE_GPA": ".indentation",
    "AreaFunction": ".indentation", "IndentationResult": ".indentation", "Indenter": ".indentation",
    "analyse_curves": ".indentation", "oliver_pharr": ".indentation", "read_curves": ".indentation",
    "reduced_modulus_gpa": ".indentation", "synthesize_curve": ".indentation",
    "youngs_from_reduced_gpa": ".indentation",
    "MEAN_GRAIN_RANGE_UM": ".mineralogy", "Mineralogy": ".mineralogy", "SUM_TOLERANCE_WT_PCT": ".mineralogy",
    "Texture": ".mineralogy", "blend_sum_ok": ".mineralogy", "fractions_hint": ".mineralogy",
    "BLEND_SUM_TOLERANCE_PER_ORE": ".mineralogy", "blend_sum_tolerance": ".mineralogy",
    "normalised_blend": ".mineralogy",
    "CLAY_MINERALS": ".minerals", "CUSHIONING_MINERALS": ".minerals", "MICA_MINERALS": ".minerals",
    "SULFIDE_MINERALS": ".minerals", "Mineral": ".minerals", "mineral_names": ".minerals",
    "mineral_table": ".minerals", "source_table": ".minerals",
    "Blend": ".ores", "load_ore": ".ores", "reference_ores": ".ores",
    "OreTyper": ".oretyping",
    "generate_library": ".sample_library", "load_reference_samples": ".sample_library",
    "SampleTableError": ".samples", "from_mineralogies": ".samples", "read_samples": ".samples",
    "to_mineralogies": ".samples", "to_mineralogy": ".samples", "validate_samples": ".samples",
}

__all__ = [
    "FRACTURE_ENERGY_RANGE_J_KG", "HARDNESS_RANGE_GPA", "INDENTER_YOUNGS_RANGE_GPA", "MEAN_GRAIN_RANGE_UM",
    "PARTICLE_SIZE_RANGE_MM", "REDUCED_MODULUS_RANGE_GPA",
    "AreaFunction", "BLEND_SUM_TOLERANCE_PER_ORE", "Blend", "BreakageOutcomeFit", "CLAY_MINERALS",
    "CUSHIONING_MINERALS", "FractureEnergyFit", "IndentationResult", "Indenter", "MICA_MINERALS", "Mineral",
    "Mineralogy", "OreTyper", "SULFIDE_MINERALS", "SUM_TOLERANCE_WT_PCT", "SampleTableError", "SizeDependence",
    "Texture", "analyse_curves", "blend_sum_ok", "blend_sum_tolerance", "breakage_probability",
    "fit_breakage_outcomes", "fit_by_group", "fit_fracture_energy", "fit_size_dependence", "fractions_hint",
    "from_mineralogies", "generate_library", "load_ore", "load_reference_samples", "mineral_names", "mineral_table",
    "normalised_blend", "oliver_pharr", "read_curves", "read_samples", "read_single_particle", "reduced_modulus_gpa",
    "reference_ores", "sample_fracture_energies", "source_table", "synthesize_curve", "to_mineralogies",
    "to_mineralogy", "validate_samples", "validate_single_particle", "youngs_from_reduced_gpa",
]
__getattr__, __dir__ = lazy_face(__name__, _API)
