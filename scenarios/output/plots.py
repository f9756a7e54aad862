"""The PNG plots of a run and of a sweep (matplotlib, headless).

Every time plot of a run marks the feed's transitions (a line at a step, a shaded span over a
ramp, a dotted line where a preview lead first sees it) and labels its bands in the legend; a
sweep's cases may each have their own, so sweep.png marks none. Size
distributions are cumulative % passing on a log size axis with a Rosin-Rammler fit
(:func:`scenarios.run.streams.fit_rosin_rammler`); a hydrocyclone circuit adds its partition
(Tromp) curve. Units in every axis label.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from scenarios.output.labels import is_percent

#: Plot files of a run: name -> what it shows (a plot whose data the run lacks is not drawn).
PLOTS = {
    "p80.png": "product P80 against time, with the target and its ±10 µm band",
    "inputs.png": "feed rate and mill speed against time",
    "feed.png": "feed blend against time (below it the plant's hardness scale, where it varies)",
    "estimates.png": "the estimator's P80 and hardness beside the plant's",
    "energy.png": "power and specific energy against time",
    "load.png": "mill load (hold-up / nominal) against time, with the stable band",
    "psd.png": "size distributions over the run, cumulative % passing, with Rosin-Rammler fits",
    "tromp.png": "hydrocyclone partition (Tromp) curve: fraction of each size to the underflow",
}


def plot_caption(name: str, summary: dict) -> str:
    """The caption of plot ``name`` for the run of ``summary``: what that run's plot draws (a batch run
    draws its mill content's P80 and its hold-up in kg, a run without a target no target band)."""
    batch = summary.get("mode") == "batch"
    if name == "p80.png":
        what = "P80 of the mill content against time (a batch: no product stream)" if batch else (
            "product P80 against time")
        return what + (", with the target and its ±10 µm band" if summary.get("target_p80_um") is not None else "")
    if name == "load.png":
        if batch:
            return "the batch mill's hold-up [kg] against time"
        return "mill load (hold-up / nominal) against time" + (
            ", with the stable band" if summary.get("load_band_frac") else "")
    return PLOTS[name]


#: Plot file of a sweep.
SWEEP_PLOT = "sweep.png"
#: Half width of the P80 band drawn around the target [um] (the KPI p80_within_10um_frac's).
P80_BAND_UM = 10.0
DPI = 90


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def blend_text(blend: dict) -> str:
    """``{"B": 0.6, "D": 0.4}`` -> ``"60 % B / 40 % D"``."""
    return " / ".join(f"{100 * f:.0f} % {ore}" for ore, f in blend.items() if f > 0)


def mark_transitions(ax, summary: dict, label: bool = True) -> None:
    """The schedule's transitions on a time axis (legend entries only when ``label``)."""
    lead = summary.get("preview_lead_h") or 0.0
    for i, ev in enumerate(summary.get("schedule") or []):
        first = label and i == 0
        text = f"to {blend_text(ev['blend'])}"
        if ev.get("kind") == "ramp" and ev.get("ramp_h", 0) > 0:
            ax.axvspan(ev["at_h"], ev["at_h"] + ev["ramp_h"], color="tab:orange", alpha=0.12, lw=0,
                       label=f"feed ramp {text}" if label else None)
        else:
            ax.axvline(ev["at_h"], color="tab:orange", lw=1.0, label=f"feed step {text}" if label else None)
        if lead > 0 and ev["at_h"] - lead >= 0:
            ax.axvline(ev["at_h"] - lead, color="tab:orange", lw=0.8, ls=":",
                       label=f"seen by the preview ({lead:g} h ahead)" if first else None)


def _time_axes(plt, rows: int, height: float):
    fig, axes = plt.subplots(rows, 1, figsize=(8, height), sharex=True, squeeze=False)
    return fig, list(axes[:, 0])


def plot_p80(plt, result):
    fr, s = result.frame, result.summary
    t = fr["time_h"].to_numpy(float)
    fig, (ax,) = _time_axes(plt, 1, 3.4)
    if "p80_um" in fr:
        ax.plot(t, fr["p80_um"], label="P80, plant")
    else:
        ax.plot(t, fr["content_p80_um"], label="P80 of the mill content (batch)")
    for col in ("p80_analyser_um", "p80_measured_um"):
        if col in fr:
            ax.step(t, fr[col], where="post", lw=0.7, alpha=0.7, label="P80, analyser")
            break
    if "recorded_p80_um" in fr:
        ax.plot(t, fr["recorded_p80_um"], lw=0.8, alpha=0.7, label="P80, recorded")
    target = s.get("target_p80_um")
    if target is not None:
        ax.axhline(target, color="k", ls="--", lw=1, label=f"target {target:g} µm")
        ax.axhspan(target - P80_BAND_UM, target + P80_BAND_UM, color="0.85", alpha=0.6, lw=0,
                   label=f"target ± {P80_BAND_UM:g} µm")
    mark_transitions(ax, s)
    ylabel = "product P80 [µm]" if "p80_um" in fr else "P80 of the mill content [µm]"
    ax.set(xlabel="time [h]", ylabel=ylabel, title=s["scene"])
    ax.legend(fontsize=7, ncol=2)
    return fig


def plot_inputs(plt, result):
    fr = result.frame
    t = fr["time_h"].to_numpy(float)
    fig, (a1, a2) = _time_axes(plt, 2, 4.6)
    for ax, col, label in ((a1, "feed_tph", "fresh feed [t/h]"), (a2, "speed_frac_critical",
                                                                     "speed [fraction of critical]")):
        ax.step(t, fr[col], where="post", label="run")
        if f"recorded_{col}" in fr:
            ax.plot(t, fr[f"recorded_{col}"], lw=0.8, alpha=0.7, label="recorded")
        mark_transitions(ax, result.summary, label=ax is a1)
        ax.set_ylabel(label)
    a1.legend(fontsize=7)
    a2.set_xlabel("time [h]")
    return fig


def plot_feed(plt, result):
    """The blend; below it the hardness scale and a history's fit residual when they vary."""
    fr = result.frame
    cols = [c for c in fr.columns if c.startswith("blend_") and c.endswith("_frac")]
    if not cols:
        return None
    t = fr["time_h"].to_numpy(float)
    varies = [c for c in ("hardness_scale", "history_fit_residual_wt_pct") if c in fr and fr[c].nunique() > 1]
    fig, axes = _time_axes(plt, 2 if varies else 1, 4.6 if varies else 3.0)
    a1 = axes[0]
    a1.stackplot(t, 100 * fr[cols].to_numpy(float).T, labels=[c[len("blend_"):-len("_frac")] for c in cols],
                 alpha=0.8, step="post")
    mark_transitions(a1, result.summary, label=False)
    a1.set(ylabel="feed blend [% by mass]", ylim=(0, 100))
    a1.legend(fontsize=7, title="ore", title_fontsize=7, loc="lower left")
    if not varies:
        a1.set_xlabel("time [h]")
        return fig
    a2 = axes[1]
    a2.plot(t, fr["hardness_scale"], label="hardness scale (plant)")
    if "history_fit_residual_wt_pct" in fr:
        ax = a2.twinx()
        ax.plot(t, fr["history_fit_residual_wt_pct"], color="tab:red", lw=0.7, label="mineralogy fit residual")
        ax.set_ylabel("fit residual [wt%]")
        ax.legend(fontsize=7, loc="upper right")
    mark_transitions(a2, result.summary, label=False)
    a2.set(xlabel="time [h]", ylabel="hardness scale [-]\n(1 = as calibrated)")
    a2.legend(fontsize=7, loc="upper left")
    return fig


def plot_estimates(plt, result):
    fr = result.frame
    est = "p80_est_um" if "p80_est_um" in fr else "p80_model_um"  # an older frame has the model's alone
    if "hardness_est" not in fr or est not in fr:
        return None
    t = fr["time_h"].to_numpy(float)
    fig, (a1, a2) = _time_axes(plt, 2, 4.6)
    a1.plot(t, fr["p80_um"], label="plant (truth)")
    # the estimate of the plant's P80 is the model's through the estimated bias and gain, not the model's
    a1.plot(t, fr[est], ls="--", label="estimate of the plant's P80")
    if est != "p80_model_um" and "p80_model_um" in fr and not np.allclose(fr[est], fr["p80_model_um"], rtol=0,
                                                                          atol=1e-9, equal_nan=True):
        a1.plot(t, fr["p80_model_um"], ls=":", lw=0.9, label="estimator's model, before its P80 bias")
    if "p80_measured_um" in fr:
        a1.step(t, fr["p80_measured_um"], where="post", lw=0.7, alpha=0.6, label="analyser")
    a1.set_ylabel("product P80 [µm]")
    a2.plot(t, fr["hardness_scale"], label="plant (truth)")
    a2.plot(t, fr["hardness_est"], ls="--", label="estimate")
    a2.set(xlabel="time [h]", ylabel="hardness scale [-]")
    for ax in (a1, a2):
        mark_transitions(ax, result.summary, label=False)
        ax.legend(fontsize=7)
    return fig


def plot_energy(plt, result):
    fr = result.frame
    if "power_kw" not in fr:
        return None
    t = fr["time_h"].to_numpy(float)
    fig, (a1, a2) = _time_axes(plt, 2, 4.6)
    a1.plot(t, fr["power_kw"])
    a1.set_ylabel("mill power [kW]")
    if "specific_energy_kwh_t" in fr:
        a2.plot(t, fr["specific_energy_kwh_t"])
    # the column is the instant's power / feed rate (a batch's energy so far / charge), not the run's KPI
    how = "energy so far / charge" if result.summary.get("mode") == "batch" else "power / feed rate"
    a2.set(xlabel="time [h]", ylabel=f"specific energy [kWh/t]\n({how})")
    for ax in (a1, a2):
        mark_transitions(ax, result.summary, label=ax is a1)
    if a1.get_legend_handles_labels()[0]:
        a1.legend(fontsize=7)
    return fig


def plot_load(plt, result):
    fr, s = result.frame, result.summary
    t = fr["time_h"].to_numpy(float)
    fig, (ax,) = _time_axes(plt, 1, 3.4)
    if "load_frac" in fr:
        ax.plot(t, fr["load_frac"], label="load")
        band = s.get("load_band_frac")
        if band:
            ax.axhspan(band[0], band[1], color="0.9", lw=0, label=f"stable band {band[0]:g}-{band[1]:g}")
        ax.set(ylabel="mill load [hold-up / nominal]")
    else:
        ax.plot(t, fr["holdup_t"] * 1000, label="hold-up")
        ax.set(ylabel="hold-up [kg] (batch)")
    mark_transitions(ax, s)
    ax.set(xlabel="time [h]")
    ax.legend(fontsize=7)
    return fig


def _psd_panel(ax, psd, title: str) -> None:
    from twin import RosinRammler

    from scenarios.run.streams import fit_rosin_rammler

    sizes = np.asarray(psd.columns, float)
    fine = np.geomspace(sizes.min(), sizes.max(), 200)
    last = len(psd) - 1
    for k, ((time_h, row), color) in enumerate(zip(psd.iterrows(), _colors(len(psd)))):
        passing = row.to_numpy(float)
        ax.semilogx(sizes, 100 * passing, "o-", ms=3, lw=0.5, color=color, label=f"t = {time_h:.3g} h")
        x63, n = fit_rosin_rammler(sizes, passing)
        if k in (0, last) and np.isfinite(n):  # the fits of the first and the last only: legible
            ax.semilogx(fine, 100 * RosinRammler(x63, n).passing(fine), "--", lw=1.0, color=color,
                        label=f"Rosin-Rammler at {time_h:.3g} h: x63 {x63:.3g} µm, n {n:.2f}")
    ax.set(xlabel="size [µm]", ylabel="cumulative passing [%]", title=title, ylim=(0, 101))
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=6)


def _colors(n: int):
    import matplotlib

    return matplotlib.colormaps["viridis"](np.linspace(0, 0.9, max(n, 1)))


def plot_psd(plt, result):
    panels = [(p, p.attrs.get("what", "product")) for p in (result.psd, result.mill_psd)
              if p is not None and len(p)]
    if not panels:
        return None
    fig, axes = plt.subplots(1, len(panels), figsize=(6.2 * len(panels), 4.4), squeeze=False)
    for ax, (psd, what) in zip(axes[0], panels):
        _psd_panel(ax, psd, what)
    return fig


def plot_tromp(plt, result):
    tables = {when: t for when, t in (result.streams or {}).items() if "partition_to_underflow_frac" in t}
    if not tables:
        return None
    fig, ax = plt.subplots(figsize=(6.2, 4.2))
    fr = result.frame
    for (when, table), ls in zip(tables.items(), ("--", "-")):
        i = 0 if when == "start" else len(fr) - 1
        d50 = f", d50c {fr['cyclone_d50c_um'].iloc[i]:.0f} µm" if "cyclone_d50c_um" in fr else ""
        ax.semilogx(table["size_mid_um"], table["partition_to_underflow_frac"], ls, marker="o", ms=3,
                    label=f"{when} of the run (t = {fr['time_h'].iloc[i]:.3g} h){d50}")
    ax.set(xlabel="size [µm] (class geometric mean)", ylabel="fraction to underflow [-]", ylim=(0, 1.02),
           title="hydrocyclone partition curve (water bypass included)")
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=7)
    return fig


_DRAW = {"p80.png": plot_p80, "inputs.png": plot_inputs, "feed.png": plot_feed, "estimates.png": plot_estimates,
         "energy.png": plot_energy, "load.png": plot_load, "psd.png": plot_psd, "tromp.png": plot_tromp}


def _save(plt, fig, path: Path) -> Path:
    from matplotlib.ticker import ScalarFormatter

    for ax in fig.axes:  # values as they are (150.2 um), never as an offset (+1.5e2)
        fmt = ax.yaxis.get_major_formatter()
        if isinstance(fmt, ScalarFormatter):
            fmt.set_useOffset(False)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def write_plots(result, folder: Path) -> list[Path]:
    """The PNG plots of a run into ``folder`` (those of :data:`PLOTS` its data allows); returns
    the files written."""
    plt = _plt()
    written = []
    for name in PLOTS:
        fig = _DRAW[name](plt, result)
        if fig is not None:
            written.append(_save(plt, fig, Path(folder) / name))
    return written


#: KPIs compared in the sweep figure: key -> axis label.
SWEEP_KPIS = {"p80_iae_um_h": "P80 IAE [µm h]", "p80_within_10um_frac": "P80 within ±10 µm [% of samples]",
              "specific_energy_kwh_t": "specific energy [kWh/t]", "throughput_tph": "throughput [t/h]"}


def case_labels(table) -> list[str]:
    """``case i: key=value, ...`` for every row of a sweep table: a key by its last part, or by its whole
    path where two varied keys end alike (feed.blend and feed.schedule[0].blend were both 'blend')."""
    varied = table.attrs.get("varied") or [c for c in table.columns if c not in ("case", "error")][:1]
    last = [k.split(".")[-1] for k in varied]
    names = [k if last.count(short) > 1 else short for k, short in zip(varied, last)]
    return [f"{row['case']}: " + ", ".join(f"{n}={row[k]}" for n, k in zip(names, varied))
            for _, row in table.iterrows()]


def write_sweep_plot(table, traces, folder: Path, target_p80_um: float | None = None) -> Path:
    """``sweep.png``: P80 of every case against time (top) and the KPIs of :data:`SWEEP_KPIS`
    per case (bars; a failed case has none). ``traces``: long table with ``case``, ``time_h``,
    ``p80_um``."""
    plt = _plt()
    labels = case_labels(table)
    kpis = [k for k in SWEEP_KPIS if k in table.columns]
    fig = plt.figure(figsize=(10, 7))
    grid = fig.add_gridspec(2, max(len(kpis), 1), height_ratios=(1.3, 1))
    top = fig.add_subplot(grid[0, :])
    colors = _colors(len(table))
    p80 = "p80_um" if traces is None or "p80_um" in traces else "content_p80_um"  # batch: the mill content's
    for (case, label), color in zip(zip(table["case"], labels), colors):
        tr = traces[traces["case"] == case] if traces is not None and len(traces) else None
        if tr is not None and len(tr):
            top.plot(tr["time_h"], tr[p80], color=color, label=label)
    if target_p80_um is not None:
        top.axhline(target_p80_um, color="k", ls="--", lw=1, label=f"target {target_p80_um:g} µm")
    ylabel = "product P80 [µm]" if p80 == "p80_um" else "P80 of the mill content [µm]"
    top.set(xlabel="time [h]", ylabel=ylabel, title=f"sweep of {table.attrs.get('scene', '')}")
    top.legend(fontsize=7, ncol=2)
    for j, key in enumerate(kpis):
        ax = fig.add_subplot(grid[1, j])
        scale = 100.0 if is_percent(key) else 1.0  # a share as the report and the workbook show it
        ax.bar(np.arange(len(table)), scale * table[key].astype(float), color=colors)
        ax.set_xticks(np.arange(len(table)), [str(c) for c in table["case"]])
        ax.set(xlabel="case", title=SWEEP_KPIS[key])
        ax.title.set_fontsize(9)
    return _save(plt, fig, Path(folder) / SWEEP_PLOT)
