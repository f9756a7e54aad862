"""The PNG plots of a run (matplotlib, headless)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: Plot files: name -> what it shows.
PLOTS = {
    "p80.png": "product P80 against time, with the target",
    "inputs.png": "feed rate and mill speed against time",
    "energy.png": "power and specific energy against time",
    "load.png": "mill load (hold-up / nominal) against time, with the band",
    "psd.png": "size distributions at several times",
}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_plots(result, folder: Path) -> list[Path]:
    """The PNG plots of a run into ``folder``; returns the files written."""
    plt = _plt()
    fr = result.frame
    t = fr["time_h"].to_numpy(float)
    target = result.summary.get("target_p80_um")
    written = []

    def save(fig, name):
        fig.tight_layout()
        path = folder / name
        fig.savefig(path, dpi=90)
        plt.close(fig)
        written.append(path)

    fig, ax = plt.subplots(figsize=(8, 3.2))
    if "p80_um" in fr:
        ax.plot(t, fr["p80_um"], label="P80 (plant)")
    else:
        ax.plot(t, fr["content_p80_um"], label="P80 of the mill content (batch)")
    for col in ("p80_analyser_um", "p80_measured_um"):
        if col in fr:
            ax.step(t, fr[col], where="post", lw=0.7, alpha=0.6, label="P80 (analyser)")
            break
    if "recorded_p80_um" in fr:
        ax.plot(t, fr["recorded_p80_um"], lw=0.8, alpha=0.7, label="P80 (recorded)")
    if target is not None:
        ax.axhline(target, color="k", ls="--", lw=1, label=f"target {target:g} um")
        ax.axhspan(target - 10, target + 10, color="0.85", alpha=0.6, lw=0)
    ax.set(xlabel="time [h]", ylabel="P80 [um]", title=result.summary["scene"])
    ax.legend(fontsize=8)
    save(fig, "p80.png")

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 4.5), sharex=True)
    a1.plot(t, fr["feed_tph"], label="run")
    if "recorded_feed_tph" in fr:
        a1.plot(t, fr["recorded_feed_tph"], lw=0.8, alpha=0.7, label="recorded")
        a1.legend(fontsize=8)
    a1.set_ylabel("feed [t/h]")
    a2.plot(t, fr["speed_frac_critical"], label="run")
    if "recorded_speed_frac_critical" in fr:
        a2.plot(t, fr["recorded_speed_frac_critical"], lw=0.8, alpha=0.7, label="recorded")
    a2.set(xlabel="time [h]", ylabel="speed [frac. critical]")
    save(fig, "inputs.png")

    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 4.5), sharex=True)
    if "power_kw" in fr:
        a1.plot(t, fr["power_kw"])
    a1.set_ylabel("power [kW]")
    if "specific_energy_kwh_t" in fr:
        a2.plot(t, fr["specific_energy_kwh_t"])
    a2.set(xlabel="time [h]", ylabel="specific energy [kWh/t]")
    save(fig, "energy.png")

    fig, ax = plt.subplots(figsize=(8, 3.2))
    if "load_frac" in fr:
        ax.plot(t, fr["load_frac"])
        band = result.summary.get("load_band_frac")
        if band:
            ax.axhspan(band[0], band[1], color="0.9", lw=0, label="band")
        ax.set(ylabel="load [hold-up / nominal]")
    else:
        ax.plot(t, fr["holdup_t"] * 1000)
        ax.set(ylabel="hold-up [kg] (batch)")
    ax.set(xlabel="time [h]")
    save(fig, "load.png")

    if result.psd is not None and len(result.psd):
        fig, ax = plt.subplots(figsize=(6.5, 4))
        sizes = np.asarray(result.psd.columns, float)
        for time_h, row in result.psd.iterrows():
            ax.semilogx(sizes, 100 * row.to_numpy(float), marker=".", label=f"t = {time_h:.3g} h")
        what = result.psd.attrs.get("what", "product")
        ax.set(xlabel="size [um]", ylabel="cumulative passing [%]", title=f"{what} size distribution")
        ax.grid(True, which="both", lw=0.3)
        ax.legend(fontsize=8)
        save(fig, "psd.png")
    return written
