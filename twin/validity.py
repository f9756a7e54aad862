"""Where a state of the twin lies outside what its models describe, one note each (empty when
inside): a hold-up beyond the mill filled to its shell (:meth:`twin.Mill.max_holdup_t`: the mill
would overflow), a speed where the charge centrifuges (:func:`twin.mill.centrifuging_note`) and,
with the rheology effect, a slurry past jamming (:func:`twin.effects.rheology.jamming_note`),
and in a hydrocyclone circuit a roping underflow (:func:`roping_note`) or a feed pressure outside
what cyclones run at (:func:`pressure_note`); a batch charge off the mill's stable load (:func:`batch_charge_note`).
Every steady state carries them (:attr:`twin.solve.SteadyState.notes`), every trajectory states
them over its samples (:func:`trajectory_notes`, :attr:`twin.solve.Trajectory.notes`; a scene's
run warns with them)."""

from __future__ import annotations

import math
from numbers import Real

import numpy as np

from .mill import CENTRIFUGING_FRAC_CRITICAL, centrifuging_note


#: Underflow solids [% by volume] at which hydrocyclones rope (the air core collapses, the underflow
#: leaves as a solid rope and coarse solids go to the overflow): ~50-60 % (Laguitton 1985, SPOC manual
#: ch. 3.1; Plitt, Conil & Broussaud 1990, Miner. Eng. 3, 533-535; Concha et al. 1996, Int. J. Miner.
#: Process. 44-45, 743-749). A design is noted from the band's lower edge; Plitt's equations do not see it.
ROPING_UNDERFLOW_SOLIDS_VOL_PCT = (50.0, 60.0)


def underflow_volume_pct(spec, outputs: dict) -> float:
    """The cyclone underflow's solids % by volume, at its own solids density where the ores' differ."""
    from .effects.classification import solids_volume_pct

    rho = float(outputs.get("underflow_solids_density_t_m3", spec.solids_density_t_m3))
    return float(solids_volume_pct(float(outputs["underflow_solids_frac"]), rho))


def roping_note(spec, outputs: dict) -> str:
    """A note when a hydrocyclone circuit's underflow (``outputs['underflow_solids_frac']``, by mass)
    is as dense as cyclones rope at (:data:`ROPING_UNDERFLOW_SOLIDS_VOL_PCT`), else ""."""
    if "underflow_solids_frac" not in outputs:
        return ""
    lo, hi = ROPING_UNDERFLOW_SOLIDS_VOL_PCT
    mass = float(outputs["underflow_solids_frac"])
    vol_pct = underflow_volume_pct(spec, outputs)
    if not vol_pct >= lo:
        return ""
    return (f"the cyclone underflow is {vol_pct:.3g} % solids by volume ({100 * mass:.3g} % by "
            f"mass), {'above' if vol_pct > hi else 'within'} the {lo:g}-{hi:g} % at which hydrocyclones rope "
            "(Laguitton 1985; Plitt, Conil & Broussaud 1990; Concha et al. 1996): Plitt's equations do not describe "
            "a roping cyclone, which sends coarse solids to the overflow; a larger apex (more water to the "
            "underflow) keeps it below")


#: Operating work indices [kWh/t] a ground ore may have: Bond's (1961) laboratory work indices of
#: ores and rocks run from ~5 to ~30 (the extremes of his table: calcined clay 1.4, emery 58), and a
#: circuit's operating index is at or above its ore's. Austin's rate in 1/h typed as 1/min (60x) gave
#: 2.2 kWh/t (a Moly-Cop alpha0 for sizes in mm, 90x, beside a given net power: 5.2, not caught).
WORK_INDEX_RANGE_KWH_T = (5.0, 60.0)


#: Specific energies [kWh/t] a ball mill draws: some 3-25 kWh/t (Bond's work index times the size reduction's
#: term), so a power or feed outside this range is one in other units, or a feed rate of another mill.
SPECIFIC_ENERGY_RANGE_KWH_T = (0.5, 100.0)


def nominal_feed_note(mill) -> str:
    """A note when a mill's nominal feed [t/h] is not one its net power at nominal speed grinds
    (:data:`SPECIFIC_ENERGY_RANGE_KWH_T`), else "": a Mill made from another (``Mill.with_`` of new dimensions)
    keeps that mill's nominal feed, which a twin's default feed then is (a 3 m mill fed the lab mill's
    0.031 t/h ground to 1.6 um, the notes blaming the breakage rates' units)."""
    from .mill import power_kw

    power = float(power_kw(mill, mill.speed_nominal_frac_critical))
    energy = power / mill.feed_nominal_tph
    lo, hi = SPECIFIC_ENERGY_RANGE_KWH_T
    if lo <= energy <= hi:
        return ""
    return (f"mill {mill.name!r}: its nominal feed {mill.feed_nominal_tph:.4g} t/h at its {power:.4g} kW (nominal "
            f"speed) is {energy:.3g} kWh/t, outside the {lo:g}-{hi:g} kWh/t ball mills draw; a Mill made from another "
            "(with_ of new dimensions) keeps that mill's feed_nominal_tph, the twin's default feed: give this mill's "
            "own (with_(feed_nominal_tph=...))")


def work_index_note(spec, outputs: dict, product_mass) -> str:
    """A note when the state's operating work index W_io = E / (10 (P80^-1/2 - F80^-1/2)) (Bond's
    law, sizes in um, E the net specific energy kWh/t; Rowland 1972) lies outside
    :data:`WORK_INDEX_RANGE_KWH_T`: the breakage rates are then likely in other units than their
    keys say, else ""."""
    from .sizes import pxx_um

    energy = outputs.get("specific_energy_kwh_t")
    if energy is None or not np.isfinite(energy) or not np.sum(product_mass) > 0:
        return ""
    return _work_index_text(spec, float(energy), pxx_um(spec.grid, product_mass), outputs.get("load_frac"))


def _work_index_text(spec, energy: float, p80: float, load: float | None = None, f80: float | None = None) -> str:
    """:func:`work_index_note` of a specific energy [kWh/t] and product P80 [um] at a load [-] (outside the
    mill's stable band the note asks about the feed too); ``f80``: the feed's P80 if known."""
    from .sizes import pxx_um

    f80 = pxx_um(spec.grid, spec.feed_frac) if f80 is None else f80
    w_io = _work_index(energy, p80, f80)
    lo, hi = WORK_INDEX_RANGE_KWH_T
    if not np.isfinite(w_io) or lo <= w_io <= hi:
        return ""
    why = ("are the breakage rates in the units their keys say (Austin's a_per_min per minute; Moly-Cop's "
           "alpha0_t_kwh for sizes in um)?")
    band = spec.mill.stable_band
    if load is not None and np.isfinite(load) and not band[0] <= load <= band[1]:
        # a starved or flooded mill is no ore's either: 0.003 t/h into the lab mill asked about the rates' units
        why += f" Or is the feed far from what the mill takes (its load is {load:.3g} of its nominal)?"
    return (f"the operating work index is {w_io:.3g} kWh/t ({float(energy):.3g} kWh/t from F80 {f80:.4g} to P80 "
            f"{p80:.4g} um, Bond's law), outside the {lo:g}-{hi:g} of ores (Bond 1961): {why}")


def _work_index(energy: float, p80: float, f80: float) -> float:
    """Bond's operating work index [kWh/t] of a specific energy [kWh/t] from F80 to P80 [um]; NaN when undefined."""
    if not (np.isfinite(energy) and np.isfinite(p80) and p80 < f80):
        return float("nan")
    return float(energy) / (10.0 * (p80 ** -0.5 - f80 ** -0.5))


def pressure_note(outputs: dict, nominal_kpa: float | None = None) -> str:
    """A note when a hydrocyclone circuit's feed pressure (``outputs['cyclone_pressure_kpa']``, Plitt's
    equation or a survey's) lies outside the range cyclones run at, else "": a cyclone's sizes in m for cm put
    it at 1e8 kPa, a survey's psi read as kPa 6.9 times low. ``nominal_kpa``: the cyclones' pressure at the
    model's nominal feed (:func:`nominal_pressure_kpa`); when it lies within the range, units do not explain
    the state's pressure, its flow does (a feed stop drops it to a fraction of a kPa), and the note says so."""
    if "cyclone_pressure_kpa" not in outputs or not outputs.get("throughput_tph", 1.0) > 0.0:
        return ""  # without a product nothing flows to the cyclones: the pressure of the model's floored flow is no state
    from .effects.classification import CYCLONE_PRESSURE_RANGE_KPA

    lo, hi = CYCLONE_PRESSURE_RANGE_KPA
    p_kpa = float(outputs["cyclone_pressure_kpa"])
    if lo <= p_kpa <= hi or not np.isfinite(p_kpa):  # NaN: no flow to the cyclones (a stopped mill's sample)
        return ""
    text = (f"the cyclone feed pressure is {p_kpa:.4g} kPa, outside the {lo:g}-{hi:g} kPa (5-40 psi) grinding "
            "cyclones run at")
    if nominal_kpa is not None and lo <= nominal_kpa <= hi:  # in range at the nominal feed: not the units
        why = "below the nominal (a feed stop or a lower feed)" if p_kpa < lo else "above the nominal (a surge)"
        return (f"{text}, where they run at {nominal_kpa:.4g} kPa at the nominal feed: the flow to them is {why}, "
                "not a units mistake, and Plitt's equations extrapolate there")
    return f"{text}: are the cyclone's sizes in cm, and a survey's pressure in kPa, not psi?"


def nominal_pressure_kpa(model) -> float | None:
    """Plitt's pressure [kPa] of a hydrocyclone circuit's cyclones at the model's nominal feed (a
    parameter of its classification), or None without cyclones."""
    design = model.parameters.get("cyclone_pressure_kpa")
    return float(design[0]) if design else None


def nominal_pressure_note(model) -> str:
    """:func:`pressure_note` of the cyclones at the model's nominal feed (Plitt's pressure there, a
    parameter of its classification), worded to follow an overload or overflow: cyclone sizes in
    inches (1049 kPa at nominal) overloaded the mill and the feed was blamed alone. "" if in range."""
    design = nominal_pressure_kpa(model)
    note = pressure_note({"cyclone_pressure_kpa": design}) if design is not None else ""
    return f"At the nominal feed {note}" if note else ""


#: The shortest nominal residence time [h] of a mill's charge taken as meant: 30 s, several times
#: below the sized industrial mills' (2.6-4.9 min at 31-1000 t/h) and the laboratory mill's (25 min
#: at 31 kg/h); a nominal feed in kg/h given as t/h puts the laboratory mill at 1.5 s.
MIN_NOMINAL_RESIDENCE_H = 30.0 / 3600.0


def residence_note(spec) -> str:
    """A note when the mill's nominal hold-up over its nominal feed is below
    :data:`MIN_NOMINAL_RESIDENCE_H` (a nominal feed a thousand times too large), else ""."""
    tau_h = spec.holdup_nominal_t / spec.feed_nominal_tph
    if not tau_h < MIN_NOMINAL_RESIDENCE_H:
        return ""
    return (f"mill {spec.mill.name!r} holds its nominal charge ({spec.holdup_nominal_t:.3g} t) for "
            f"{3600 * tau_h:.3g} s at its nominal feed ({spec.feed_nominal_tph:.4g} t/h): ball mills hold theirs minutes; is "
            "feed_nominal_tph in kg/h?")


def blend_density_t_m3(spec, fractions) -> float:
    """The solids density [t/m3] of a blend of the spec's components (mass ``fractions`` in their order): the
    harmonic mean of their densities (the nominal blend's when they share one)."""
    return spec.solids_density_t_m3 / float(spec.blend_volume_ratio(np.asarray(fractions, float)))


def shell_capacity_t(spec, holdup_t, load_frac=None):
    """What the mill holds filled to its shell [t] of a content whose hold-up is ``holdup_t`` at ``load_frac`` (its
    volume over the nominal hold-up's, the ``holdup`` effect's output; arrays alike): the shell's volume at the
    content's own density. Without a load, or for an empty mill, at the nominal blend's density."""
    shell = spec.mill.max_holdup_t(spec.solids_density_t_m3)
    if load_frac is None or spec.volume_weights() is None:
        return shell
    packed = np.asarray(load_frac, float) * spec.holdup_nominal_t
    return np.where(packed > 0, shell * np.asarray(holdup_t, float) / np.where(packed > 0, packed, 1.0), shell)


def overflow_note(holdup_t: float, capacity_t: float) -> str | None:
    """A note when a hold-up [t] exceeds the mill's shell capacity [t], else None."""
    if not holdup_t > capacity_t:
        return None
    return (f"hold-up {holdup_t:.4g} t is more than the mill holds filled to its shell ({capacity_t:.4g} t): "
            "it would overflow; these numbers extrapolate the model beyond the mill")


def state_notes(spec, effect_names, speed_frac_critical: float, holdup_t: float,
                clay_frac: float | None = None, outputs: dict | None = None, product_mass=None,
                nominal_pressure_kpa: float | None = None) -> list[str]:
    """The notes of a state of a model built from ``spec`` (:class:`twin.model.ModelSpec`) with
    ``effect_names``, at a speed [fraction of critical], hold-up [t] and hold-up clay fraction
    (and the state's other ``outputs``, for the circuit's water balance, and its product's mass
    per size class, for a P80 the grid does not resolve; and the cyclones' pressure at the nominal feed,
    :func:`nominal_pressure_kpa`, which tells a pressure's units from its flow)."""
    notes = [overflow_note(holdup_t, float(shell_capacity_t(spec, holdup_t, (outputs or {}).get("load_frac")))),
             centrifuging_note(speed_frac_critical), water_note(outputs or {}), roping_note(spec, outputs or {}),
             pressure_note(outputs or {}, nominal_pressure_kpa),
             sink_note(spec.grid, product_mass) if product_mass is not None else "", residence_note(spec),
             work_index_note(spec, outputs or {}, product_mass) if product_mass is not None else ""]
    k_clay = _clay_crowding(spec, effect_names)
    if k_clay is not None and clay_frac is not None:
        from .effects.rheology import jamming_note

        notes.append(jamming_note(clay_frac, k_clay))
    return [n for n in notes if n]


#: The product's share below the grid's finest class bound from which its P80 lies in the sink.
SINK_NOTE_FRAC = 0.8


def sink_note(grid, product_mass) -> str:
    """A note when 80 % of the product lies in the grid's sink (below its finest class bound):
    its P80 is then :func:`twin.sizes.pxx_um`'s extrapolation, not a resolved size (a feed analysis
    in mm read as um, or a breakage rate far too high, lands the whole product there)."""
    m = np.asarray(product_mass, float)
    if not m.sum() > 0:
        return ""
    sink = float(m[-1] / m.sum())
    return _sink_text(f"{sink:.0%}", grid.upper_um[-1]) if sink >= SINK_NOTE_FRAC else ""


def _sink_text(share: str, finest_um: float, what: str = "product") -> str:
    return (f"{share} of the {what} lies below the finest size class ({finest_um:.3g} um): its P80 is "
            "extrapolated, not resolved (a finer mill.size_classes would resolve it; or check the feed's sizes "
            "for mm given as um and the breakage rates' units)")


def water_shortfalls(outputs: dict) -> dict[str, float]:
    """The circuit's water additions [m3/h] that come out negative (water taken out), by output."""
    return {k: float(outputs[k]) for k in ("mill_water_m3_h", "sump_water_m3_h")
            if k in outputs and float(outputs[k]) < 0.0}


def water_note(outputs: dict) -> str:
    """A note when the closed circuit's water balance (twin.effects.classification) needs water
    taken out of the mill's feed or the sump: the cyclone underflow carries more water than the
    mill discharges at its solids fraction (or the cyclone feed less than the discharge), which no
    plant can run; typically cyclones far from their operating pressure, with a large water bypass."""
    short = water_shortfalls(outputs)
    if not short:
        return ""
    more = ", ".join(f"{k} {float(outputs[k]):.3g}" for k in ("cyclone_pressure_kpa", "cyclone_water_bypass_frac")
                     if k in outputs)
    taken = ", ".join(f"{k} {v:.3g}" for k, v in short.items())
    return (f"the circuit's water balance needs water taken out ({taken}): no plant runs so; the cyclones' "
            "operating point is far from a design's" + (f" ({more})" if more else ""))


def _clay_crowding(spec, effect_names) -> float | None:
    """The clay-crowding coefficient a jamming check compares against, or None: without the
    rheology effect, or in a parametric model (twin.calibration.parametric), which holds a symbol
    there, not a number."""
    k_clay = spec.coefficients.get("clay_crowding_coeff")
    return k_clay if "rheology" in effect_names and isinstance(k_clay, Real) else None


def _outside_ratio(value: float, band: tuple) -> float:
    """How far ``value`` lies outside ``band`` = (lo, hi), as a ratio (lo / value or value / hi; 1 inside): the
    farthest of a stretch's samples on either side is its worst."""
    lo, hi = band
    return max(lo / value if value > 0 else math.inf, value / hi, 1.0)


def _sample_notes(frame, spec, nominal_pressure_kpa: float | None = None) -> list[str]:
    """The steady states' notes of a run's samples that read its outputs (a roping underflow, a cyclone
    pressure outside the range, a water balance that takes water out, an operating work index outside
    ores'), each with the span of samples it holds on and its text at the worst of them, and when: a run held
    a roping cyclone for an hour and said nothing its steady state said; a feed stop's 0.02 kPa was quoted as
    the 33 kPa of the stretch's last sample."""
    from .effects.classification import CYCLONE_PRESSURE_RANGE_KPA

    t = frame["time_h"].to_numpy(float)
    rows = frame.to_dict("records")
    # each check: its note of a sample, and how bad a noted sample is (larger is worse)
    checks = [(lambda r: roping_note(spec, r),
               lambda r: underflow_volume_pct(spec, r)),
              (lambda r: pressure_note(r, nominal_pressure_kpa),
               lambda r: _outside_ratio(float(r["cyclone_pressure_kpa"]), CYCLONE_PRESSURE_RANGE_KPA)),
              (water_note, lambda r: -min(water_shortfalls(r).values()))]
    if {"specific_energy_kwh_t", "p80_um", "p80_smooth_um"} <= set(frame.columns):  # p80_um then exact
        from .sizes import pxx_um

        f80 = pxx_um(spec.grid, spec.feed_frac)  # once, not per sample
        checks.append((lambda r: _work_index_text(spec, float(r["specific_energy_kwh_t"]), float(r["p80_um"]),
                                                  r.get("load_frac"), f80),
                       lambda r: _outside_ratio(_work_index(float(r["specific_energy_kwh_t"]),
                                                            float(r["p80_um"]), f80), WORK_INDEX_RANGE_KWH_T)))
    notes = []
    for check, badness in checks:
        texts = [check(r) for r in rows]
        hit = [i for i, text in enumerate(texts) if text]
        if hit:
            worst = max(hit, key=lambda i: badness(rows[i]))
            notes.append(f"from {t[hit[0]]:.4g} h to {t[hit[-1]]:.4g} h ({len(hit)} of {len(t)} samples; at worst, at "
                         f"{t[worst]:.4g} h) {texts[worst]}")
    return notes


def batch_charge_note(spec, charge_t: float, fractions=None) -> str:
    """A note when a batch charge [t] (of a blend of mass ``fractions``, the nominal one if None) lies outside the
    mill's stable load band, else "": a model without ``transport`` grinds at the rates of the mill's nominal
    hold-up, while S = S^E P / H (Herbst & Fuerstenau 1980), saturating below a powder filling of 0.5 (Austin et
    al. 1984, fig. 8.3; the ``holdup`` effect of a continuous mill), gives another charge other rates. A charge in
    lb read as kg (2.2x) ground as fast as the nominal one, without a word."""
    from .effects.holdup import RATE_SATURATION_POWDER_FILLING

    rho = spec.solids_density_t_m3 if fractions is None else blend_density_t_m3(spec, fractions)
    nominal_t = spec.mill.nominal_holdup_t(rho)
    load = charge_t / nominal_t
    lo, hi = spec.mill.stable_band
    if not charge_t > 0 or lo <= load <= hi:
        return ""
    factor = 1.0 / max(load, RATE_SATURATION_POWDER_FILLING / spec.mill.powder_filling_nominal)
    return (f"the batch charge {1000 * charge_t:.4g} kg is {load:.3g} of the mill's nominal hold-up "
            f"({1000 * nominal_t:.4g} kg of this ore), outside its stable band {lo:g}-{hi:g}: a batch grinds at the "
            f"nominal hold-up's rates, while S = S^E P / H (Herbst & Fuerstenau 1980; saturating below a powder filling "
            f"of {RATE_SATURATION_POWDER_FILLING:g}, Austin et al. 1984 fig. 8.3) makes this charge's {factor:.3g} x "
            f"them, so its product is too {'coarse' if factor > 1 else 'fine'} (a charge in t or lb for kg?)")


def trajectory_notes(frame, spec, effect_names, product_psd=None,
                     nominal_pressure_kpa: float | None = None) -> list[str]:
    """The notes of a run's samples (a frame with ``time_h`` and any of ``holdup_t``,
    ``speed_frac_critical``, ``clay_frac``), each saying when: the share of samples past the
    mill's shell and the largest hold-up, the centrifuging speed and the jammed slurry of its most
    extreme sample; when its P80 lies in the grid's sink (:func:`sink_note`; from the product's size
    snapshots, ``product_psd``: rows = times [h], columns = class upper sizes [um], values = cumulative
    fraction passing, else from the exact ``p80_um``); and the notes of its outputs (:func:`_sample_notes`; a
    hydrocyclone circuit's ``nominal_pressure_kpa``, :func:`nominal_pressure_kpa`, tells a pressure's units
    from its flow)."""
    t = frame["time_h"].to_numpy(float)
    notes = [n for n in (residence_note(spec),) if n]
    if product_psd is not None and len(product_psd):
        sink = product_psd.iloc[:, -1].to_numpy(float)  # passing the finest class's upper size: the sink's share
        deep = sink >= SINK_NOTE_FRAC
        if deep.any():
            when = product_psd.index.to_numpy(float)[deep]
            notes.append(f"from {when[0]:.4g} h to {when[-1]:.4g} h ({deep.sum()} of {len(sink)} size snapshots) "
                         + _sink_text(f"{float(sink.max()):.0%}", float(product_psd.columns[-1])))
    else:  # no snapshots: an exact P80 (a batch's of its content) below the finest class lies in the sink
        for p80, what in (("p80_um", "product"), ("content_p80_um", "mill content")):
            if {p80, p80.replace("_um", "_smooth_um")} <= set(frame.columns):
                finest = float(spec.grid.upper_um[-1])
                deep = frame[p80].to_numpy(float) < finest
                if deep.any():
                    notes.append(f"from {t[deep][0]:.4g} h to {t[deep][-1]:.4g} h ({deep.sum()} of {len(t)} samples) "
                                 + _sink_text(f"{SINK_NOTE_FRAC:.0%} or more", finest, what))
    notes += _sample_notes(frame, spec, nominal_pressure_kpa)
    if "transport" not in effect_names and "holdup_t" in frame.columns and len(frame):  # a batch: its charge
        blend = [f"blend_{c}_frac" for c in spec.component_names]
        shares = frame[blend].iloc[0].to_numpy(float) if set(blend) <= set(frame.columns) else None
        note = batch_charge_note(spec, float(frame["holdup_t"].iloc[0]), shares)
        notes += [note] if note else []
    if "holdup_t" in frame.columns:
        held = frame["holdup_t"].to_numpy(float)
        capacity = np.broadcast_to(shell_capacity_t(spec, held, frame["load_frac"] if "load_frac" in frame else None),
                                   held.shape)
        over = held > capacity
        if over.any():
            capacity_t = float(capacity[np.argmax(held)])
            notes.append(f"the plant's hold-up exceeds what its mill holds filled to its shell ({capacity_t:.4g} t) "
                         f"on {over.mean():.0%} of the samples, from {t[over][0]:.4g} h to {t[over][-1]:.4g} h (at "
                         f"most {held.max():.4g} t): the mill would overflow, and the numbers of those samples "
                         "extrapolate the model beyond the mill")
    if "speed_frac_critical" in frame.columns:
        speed = frame["speed_frac_critical"].to_numpy(float)
        note = centrifuging_note(float(np.nanmax(speed)))
        if note:
            fast = t[speed > CENTRIFUGING_FRAC_CRITICAL]
            notes.append(f"from {fast[0]:.4g} h to {fast[-1]:.4g} h the {note}")
    k_clay = _clay_crowding(spec, effect_names)
    if k_clay is not None and "clay_frac" in frame.columns:
        from .effects.rheology import jamming_clay_frac, jamming_note

        clay = frame["clay_frac"].to_numpy(float)
        note = jamming_note(float(np.nanmax(clay)), k_clay)
        if note:
            jammed = t[clay > jamming_clay_frac(k_clay)]
            notes.append(f"from {jammed[0]:.4g} h to {jammed[-1]:.4g} h {note}")
    return notes
