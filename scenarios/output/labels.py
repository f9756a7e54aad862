"""What each KPI means, with its unit, and how it is printed: the report's table and the
workbook's KPI sheet read the same labels (and the same calibration and preset file texts)."""

from twin.calibration import FAST_LABEL

#: KPI key -> (label, format).
KPI_LABELS = {
    # the plant's P80, not the analyser's reading (scenarios.run.kpis): what the product was, not what was seen
    "p80_iae_um_h": ("P80 integral absolute error, the plant's P80 [µm h]", "{:.4g}"),
    "p80_within_10um_frac": ("share of samples with the plant's P80 within ±10 µm of target [%]", "{:.1%}"),
    "specific_energy_kwh_t": ("specific energy [kWh/t]", "{:.4g}"),
    "throughput_t": ("product discharged over the run (a batch: its charge) [t]", "{:.4g}"),
    "throughput_tph": ("throughput, mean product rate [t/h]", "{:.4g}"),
    "load_outside_band_frac": ("share of samples with load outside its band [%]", "{:.1%}"),
    "solve_time_median_s": ("controller solve time, median [s]", "{:.3g}"),
    "solve_time_p95_s": ("controller solve time, 95th percentile [s]", "{:.3g}"),
    "mass_balance_error": ("mass balance error [relative]", "{:.2e}"),
    "controller_failed_steps": ("controller steps whose solve failed", "{:d}"),
    "controller_fallback_steps": ("controller steps that applied a fallback input", "{:d}"),
    "estimator_resets": ("estimator resets (its warm-up included)", "{:d}"),
    "start_feed_tph": ("feed rate of the start state [t/h]", "{:.4g}"),
    "start_p80_um": ("P80 at the start [µm]", "{:.4g}"),
    "p80_final_um": ("final P80 [µm]", "{:.4g}"),
    "p80_mean_um": ("mean P80 (a batch: of the mill content) [µm]", "{:.4g}"),
    "p80_kpis_exclude_h": ("time without product, left out of the P80 KPIs [h]", "{:.4g}"),
    "energy_kwh": ("energy drawn [kWh]", "{:.4g}"),
    "fed_t": ("fresh feed [t]", "{:.4g}"),
    "duration_h": ("duration [h]", "{:.4g}"),
    "feed_tph_mean_diff": ("feed rate, mean of run - recorded [t/h]", "{:.4g}"),
    "feed_tph_mean_abs_diff": ("feed rate, mean |run - recorded| [t/h]", "{:.4g}"),
    "speed_frac_critical_mean_diff": ("speed, mean of run - recorded [fraction of critical]", "{:.4g}"),
    "speed_frac_critical_mean_abs_diff": ("speed, mean |run - recorded| [fraction of critical]", "{:.4g}"),
    "p80_um_mean_diff": ("P80 as the analyser reads it (no noise), mean of run - recorded [µm]", "{:.4g}"),
    "p80_um_mean_abs_diff": ("P80 as the analyser reads it (no noise), mean |run - recorded| [µm]", "{:.4g}"),
}

#: Most decimals a share is shown with before it is written as "< 0.0001 %" or "> 99.9999 %".
PERCENT_MAX_DECIMALS = 4


def percent_decimals(frac: float) -> int:
    """Decimals a share needs as a percentage (one at least) so that a share strictly between
    0 and 1 never reads 0.0 % or 100.0 % (one sample outside a band in 3000 is 99.97 %, not
    100.0 %); :data:`PERCENT_MAX_DECIMALS` at most."""
    d = 1
    while d < PERCENT_MAX_DECIMALS and _rounds_to_bound(frac, d):
        d += 1
    return d


def _rounds_to_bound(frac: float, d: int) -> bool:
    """A share strictly between 0 and 1 within half a unit of the d-th decimal of a percentage of
    0 or 100 (with a margin, so that no rounding rule, Excel's included, shows it as 0 or 100)."""
    half = 0.5 * 10.0 ** -d + 1e-9
    return 0.0 < frac < 1.0 and (100.0 * frac < half or 100.0 * frac > 100.0 - half)


def percent_text(frac: float) -> str:
    """A share as a percentage with :func:`percent_decimals` decimals; a share too close to 0 or
    1 for those says so ("< 0.0001%"), never "0%" or "100%"."""
    d = percent_decimals(frac)
    text = f"{100.0 * frac:.{d}f}%"
    if _rounds_to_bound(frac, d):
        text = f"< {10.0 ** -d:.{d}f}%" if frac < 0.5 else f"> {100.0 - 10.0 ** -d:.{d}f}%"
    return text


def is_percent(key: str) -> bool:
    """Whether a KPI is a share shown as a percentage (its label's format is a percentage)."""
    return KPI_LABELS.get(key, ("", ""))[1].endswith("%}")


def kpi_text(key: str, value) -> str:
    """A KPI's value as the report shows it: its label's format, shares by :func:`percent_text`."""
    if is_percent(key) and isinstance(value, (int, float)) and not isinstance(value, bool):
        return percent_text(float(value))
    fmt = KPI_LABELS.get(key, (key, "{:.4g}"))[1]
    return fmt.format(value)


def calibration_text(cal) -> str | None:
    """Name, file and hash of the calibration a run used (summary.json's ``calibration``)."""
    if not cal:
        return None
    sha = f", sha256 {cal['sha256'][:12]}" if cal.get("sha256") else ""
    return f"{cal.get('name')} ({cal.get('path') or 'in memory'}{sha}{FAST_LABEL if cal.get('fast') else ''})"


def preset_file_text(preset) -> str | None:
    """File and hash of the mill preset file a run's scene named (summary.json's ``mill_preset_file``), as
    :func:`calibration_text` gives the calibration's; None for a preset's name. Also the history file a run was
    fed (``history_file``) and the feed's screen analysis (``psd_file``), of the same form."""
    if not preset:
        return None
    sha = f" (sha256 {preset['sha256'][:12]})" if preset.get("sha256") else ""
    return f"{preset.get('path')}{sha}"


def replay_rows(summary: dict) -> list[tuple[str, str | None]]:
    """The recorded history a replay ran and the plant's clock at its time 0 (none: not a replay)."""
    replay = summary.get("replay")
    if not isinstance(replay, dict):
        return []
    return [("replayed history", replay.get("history")), ("history's clock at time 0", replay.get("history_start"))]


def effects_rows(summary: dict) -> list[tuple[str, str]]:
    """The run's effects as the report and workbook name them: the scene's, and the plant's when a
    [plant] table runs others (it showed the scene's alone, as if the plant had run them)."""
    scene = list(summary.get("effects") or [])
    plant = summary.get("plant_effects")
    if plant is None or set(plant) == set(scene):
        return [("effects", ", ".join(scene))]
    return [("effects (controller's model)", ", ".join(scene)), ("plant effects", ", ".join(plant))]
