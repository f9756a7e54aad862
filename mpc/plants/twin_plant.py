"""The twin as a plant: the plant protocol (:mod:`mpc.plants`) on a twin's mill model."""

from __future__ import annotations

import math

import numpy as np

from mpc.errors import MpcInputError
from twin import pxx_um
from twin.solve import ORE_CIRCULATING_LOAD_KEY, ORE_P80_KEY, has_ore_products, ore_circulating_load, ore_p80_um, step


#: Outputs every plant's ``measure`` returns (the columns the KPIs use).
PLANT_OUTPUTS = ("power_kw", "load_frac", "throughput_tph", "specific_energy_kwh_t", "holdup_t")
#: Model outputs a closed loop's row has from elsewhere (mpc.closed_loop): not measured from the model.
LOOP_OWN_COLUMNS = ("p80_um", "p80_measured_um")


class TwinPlant:
    """The plant protocol (:mod:`mpc.plants`) on a twin's :class:`twin.model.Model`: P80 from the
    product size distribution (:func:`twin.sizes.pxx_um`, nan for an empty product; a mill of several ores
    each ore's too, and in a cyclone circuit each ore's circulating load, as in an open-loop run's frame), the
    outputs :data:`PLANT_OUTPUTS` of the model (the specific energy nan at zero feed, as in
    :func:`twin.solve.simulate.outputs_frame`), and :func:`twin.solve.simulate.step`."""

    def __init__(self, model):
        self.model = model
        self.component_names = tuple(model.spec.component_names)
        self._psd_fn = model.product_psd_function()
        # a mill of several ores: each ore's product, whose sum is the product (one evaluation for both)
        self._ore_fn = model.outputs["ore_product_tph"] if has_ore_products(model) else None
        # and in a cyclone circuit each ore's underflow (its circulating load)
        self._under_fn = model.outputs.get("ore_underflow_tph") if self._ore_fn is not None else None
        # every scalar output, as an open-loop run's frame has them (a closed loop lacked feed_inventory_t,
        # so its mass balance could not be closed, and the slurry's and the contents' columns), but the
        # model's smooth P80 and analyser lag: the loop's P80 is the product's (above), its reading the sensor's
        self._outs = {k: model.outputs[k] for k in PLANT_OUTPUTS} | {
            k: fn for k, fn in model.outputs.items()
            if k not in PLANT_OUTPUTS + LOOP_OWN_COLUMNS and fn.size1_out(0) == 1}

    def disturbance(self, t_h: float, blend, hardness: float) -> np.ndarray:
        return self.model.d_vector(blend, hardness)

    def measure(self, x, u, d) -> dict:
        grid = self.model.spec.grid
        if self._ore_fn is None:
            psd, ores = np.asarray(self._psd_fn(x, u, d), float).ravel(), {}
        else:
            flows = np.asarray(self._ore_fn(x, u, d), float)
            psd = flows.sum(axis=1)  # the product per size class, added as the model adds it (ore by ore)
            ores = {ORE_P80_KEY.format(k): v for k, v in ore_p80_um(grid, self.component_names, flows).items()}
        if self._under_fn is not None:
            loads = ore_circulating_load(self.component_names, self._under_fn(x, u, d), float(np.ravel(u)[0]),
                                         np.ravel(d)[:len(self.component_names)])
            ores |= {ORE_CIRCULATING_LOAD_KEY.format(k): v for k, v in loads.items()}
        vals = {"p80_um": pxx_um(grid, psd) if psd.sum() > 0 else math.nan} | ores
        vals.update({key: float(fn(x, u, d)) for key, fn in self._outs.items()})
        if not float(np.asarray(u, float).ravel()[0]) > 0.0:  # energy per tonne fed: undefined without
            vals["specific_energy_kwh_t"] = math.nan       # feed (the model's division floor gives ~1e7)
        return vals

    def step(self, x, u, d, dt_h: float):
        return step(self.model, x, u, d, dt_h)


def as_plant(plant):
    """``plant`` itself if it follows the plant protocol, a :class:`TwinPlant` if it is a
    twin's model; else an :class:`MpcInputError` naming what is missing."""
    needed = ("component_names", "disturbance", "measure", "step")
    if all(hasattr(plant, a) for a in needed):
        return plant
    if hasattr(plant, "product_psd_function") and hasattr(plant, "spec"):
        return TwinPlant(plant)
    raise MpcInputError(f"The 'plant_model' parameter of run_closed_loop must be a twin Model or "
                        f"have {', '.join(needed)} (the plant protocol of mpc.plants). "
                        f"Got {type(plant).__name__}.")
