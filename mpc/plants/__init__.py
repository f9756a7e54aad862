"""Plants a controller runs against: the twin's own model (:class:`TwinPlant`) and an independent
circuit, le Roux et al. (2013) (:class:`LeRouxPlant`, with the twin matched to it).

The plant protocol (what :func:`mpc.run_closed_loop` needs of a plant):

- ``component_names``: names of the blend entries ``schedule(t)`` returns (the controller's
  components; recorded as ``blend_<name>_frac``);
- ``disturbance(t_h, blend, hardness) -> d``: the plant's own disturbance vector;
- ``measure(x, u, d) -> dict``: at least ``p80_um``, ``power_kw``, ``load_frac``,
  ``throughput_tph``, ``specific_energy_kwh_t`` and ``holdup_t`` (the hold-up that the
  cumulative fed and produced mass balance); further entries become columns of the run;
- ``step(x, u, d, dt_h) -> (x_next, fed_t, produced_t)``.
"""

from mpc.plants.leroux import LeRouxCircuit, LeRouxParameters, LeRouxPlant, MatchedTwin, matched_twin
from mpc.plants.twin_plant import PLANT_OUTPUTS, TwinPlant, as_plant

__all__ = ["LeRouxCircuit", "LeRouxParameters", "LeRouxPlant", "MatchedTwin", "PLANT_OUTPUTS", "TwinPlant",
           "as_plant", "matched_twin"]
