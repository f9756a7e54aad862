"""Why pyrite for biotite in Type B moves the throughput at constant load as it does: the change
split into its channels, each a consistent twin on the default calibration (lab mill, 70 % of
critical, nominal hold-up):

- density alone: Type B at the pyrite ore's density, breaking alike per volume (S^E per tonne
  times the density ratio, so S = S^E P / H is unchanged), the grate's cut held at Type B's
  (the volume-flow discharge alone);
- grate hold-back alone: Type B with the grate's cut of the denser pyrite ore (Stokes,
  twin.effects.classification.grate_density_factor);
- hardness alone: the pyrite ore's breakage per volume (its S^E over the density ratio) at
  Type B's density;
- cushioning alone: Type B with the pyrite ore's soft (clay + mica + chlorite) fraction (it
  slows the rates only; the power follows the clay, which does not change);
- all: the pyrite ore itself (tests/twin/test_physics_claims.py's ``pyrite_for_biotite``).

Then the whole change on each of the calibration's bootstrap replicates (laws and table step
refitted on resampled virtual particles): how often MISSION.md's claim (energy up, P80 down)
and issue 12's (tonnes down) hold under the DEM's particle scatter, with 90 % intervals.

Writes benchmarks/results/twin_pyrite_channels.csv/.md and twin_pyrite_replicates.csv/.md.
Run: ``python benchmarks/twin_pyrite_channels.py`` (~1 min).
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace

sys.path.insert(0, os.path.dirname(__file__))

import pandas as pd

from dem_common import write_table
from twin import Mineralogy, Twin, load_ore
from twin.calibration import load_calibration
from twin.calibration.uncertainty import INTERVAL_LEVEL, intervals, replicate_steady_states
from twin.effects.classification import grate_density_factor
from twin.mill import get_mill
from twin.model import Model
from twin.solve import steady_state_at_load

POINTS = 15.0


def pyrite_ore() -> Mineralogy:
    b = load_ore("B")
    wt = dict(b.wt_pct, pyrite=b.wt_pct["pyrite"] + POINTS, biotite=b.wt_pct["biotite"] - POINTS)
    return Mineralogy(wt, b.texture, name="B_pyrite")


def kpis(twin: Twin, spec=None) -> dict:
    model = twin.model if spec is None else Model(spec)
    ss = steady_state_at_load(model, twin._u(twin.mill.feed_nominal_tph, 0.70), model.d_vector(twin.nominal_blend, 1.0), 1.0)
    return {"throughput_kg_h": 1000.0 * ss.feed_tph, "p80_um": ss.p80_um,
            "specific_energy_kwh_t": ss.outputs["specific_energy_kwh_t"], "power_w": 1000.0 * ss.outputs["power_kw"],
            "residence_time_min": 60.0 * ss.outputs["holdup_t"] / ss.feed_tph}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.parse_args(argv)
    b, p = load_ore("B"), pyrite_ore()
    rb, rp = b.density_t_m3, p.density_t_m3
    tb, tp = Twin(b), Twin(p)
    sb, sp = tb.spec.breakage[0].params, tp.spec.breakage[0].params
    lab = get_mill("lab", tb.calibration.record)
    held = grate_density_factor(rp) / grate_density_factor(rb)  # the pyrite ore's cut over B's

    def grate_scaled(factor):
        return lab.with_(grate_d50_um=lab.grate_d50_um * factor)

    cases = {
        "Type B": kpis(tb),
        "density alone": kpis(Twin(b, ore_breakage={b.name: replace(sb, se_1mm_t_kwh=sb.se_1mm_t_kwh * rp / rb)},
                                   solids_density_t_m3=rp, mill=grate_scaled(1.0 / held))),
        "grate hold-back alone": kpis(Twin(b, mill=grate_scaled(held))),
        "hardness alone": kpis(Twin(b, ore_breakage={b.name: replace(sp, se_1mm_t_kwh=sp.se_1mm_t_kwh * rb / rp)})),
        "cushioning alone": kpis(tb, replace(tb.spec, soft_frac=tp.spec.soft_frac)),
        "all (pyrite ore)": kpis(tp),
    }
    base = cases["Type B"]
    rows = [{"case": name, **{k: round(v, 4) for k, v in kp.items()},
             **{f"{k}_change_pct": round(100.0 * (kp[k] / base[k] - 1.0), 2) for k in ("throughput_kg_h", "p80_um",
                                                                                 "specific_energy_kwh_t", "power_w")}}
            for name, kp in cases.items()]
    volume = 100.0 * ((cases["all (pyrite ore)"]["throughput_kg_h"] / rp) / (base["throughput_kg_h"] / rb) - 1.0)
    notes = (f"{POINTS:g} wt% pyrite for biotite in Type B at constant load (the nominal powder filling, a volume). "
             f"Densities {rb:.3f} and {rp:.3f} t/m3 ({100 * (rp / rb - 1):+.2f} %); S^E at 1 mm {sb.se_1mm_t_kwh:.4f} "
             f"and {sp.se_1mm_t_kwh:.4f} t/kWh ({100 * ((sp.se_1mm_t_kwh / rp) / (sb.se_1mm_t_kwh / rb) - 1):+.2f} % per "
             f"volume); soft fraction {tb.spec.soft_frac[0]:.3f} and {tp.spec.soft_frac[0]:.3f}; the grate's cut "
             f"x {held:.4f} for the denser ore. The ore volume "
             f"ground per hour changes by {volume:+.2f} %. Calibration: {tb.calibration.name!r}, sha256 {tb.calibration.sha256[:12]}.")
    write_table(pd.DataFrame(rows), "twin_pyrite_channels", "Pyrite for biotite: the throughput's channels", notes)
    print(notes)
    replicates(b, p)


def replicates(b: Mineralogy, p: Mineralogy) -> None:
    """The change from ``b`` to ``p`` on every bootstrap replicate of the default calibration."""
    cal = load_calibration()
    ref, pyr = (replicate_steady_states(o, cal, speed_frac_critical=0.70, at_load=True) for o in (b, p))
    changes = [{f"{k}_change_pct": 100.0 * (y[k] / x[k] - 1.0)
                for k in ("specific_energy_kwh_t", "p80_um", "throughput_tph")}
               for x, y in zip(ref, pyr) if x is not None and y is not None]
    failed = len(ref) - len(changes)
    holds = sum(c["specific_energy_kwh_t_change_pct"] > 0 > c["p80_um_change_pct"] for c in changes)
    slows = sum(c["throughput_tph_change_pct"] < 0 for c in changes)
    band = intervals(changes)
    rows = [{"kpi": k, "low_pct": round(lo, 3), "median_pct": round(mid, 3), "high_pct": round(hi, 3)}
            for k, (lo, mid, hi) in band.items()]
    notes = (f"{POINTS:g} wt% pyrite for biotite in Type B at constant load, on each of the {len(changes)} bootstrap "
             f"replicates of calibration {cal.name!r} (sha256 {cal.sha256[:12]}) whose steady states solved "
             f"({failed} failed): energy up and P80 down (MISSION.md's claim) on {holds}, tonnes per hour down "
             f"(issue 12's) on {slows}. {100 * INTERVAL_LEVEL:g} % percentile intervals of the changes.")
    write_table(pd.DataFrame(rows), "twin_pyrite_replicates", "Pyrite for biotite over the calibration's scatter", notes)
    print(notes)


if __name__ == "__main__":
    main()
