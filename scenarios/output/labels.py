"""What each KPI means, with its unit, and how it is printed: the report's table and the
workbook's KPI sheet read the same labels."""

#: KPI key -> (label, format).
KPI_LABELS = {
    "p80_iae_um_h": ("P80 integral absolute error [µm h]", "{:.4g}"),
    "p80_within_10um_frac": ("share of time P80 within ±10 µm of target [%]", "{:.1%}"),
    "specific_energy_kwh_t": ("specific energy [kWh/t]", "{:.4g}"),
    "throughput_t": ("product discharged over the run [t]", "{:.4g}"),
    "throughput_tph": ("throughput, mean product rate [t/h]", "{:.4g}"),
    "load_outside_band_frac": ("share of time load outside its band [%]", "{:.1%}"),
    "solve_time_median_s": ("controller solve time, median [s]", "{:.3g}"),
    "solve_time_p95_s": ("controller solve time, 95th percentile [s]", "{:.3g}"),
    "mass_balance_error": ("mass balance error [relative]", "{:.2e}"),
    "controller_failed_steps": ("controller steps whose solve failed", "{:d}"),
    "controller_fallback_steps": ("controller steps that applied a fallback input", "{:d}"),
    "estimator_resets": ("estimator resets (its warm-up included)", "{:d}"),
    "start_feed_tph": ("feed rate of the start state [t/h]", "{:.4g}"),
    "start_p80_um": ("P80 at the start [µm]", "{:.4g}"),
    "p80_final_um": ("final P80 [µm]", "{:.4g}"),
    "p80_mean_um": ("mean P80 [µm]", "{:.4g}"),
    "energy_kwh": ("energy drawn [kWh]", "{:.4g}"),
    "fed_t": ("fresh feed [t]", "{:.4g}"),
    "duration_h": ("duration [h]", "{:.4g}"),
    "feed_tph_mean_diff": ("feed rate, mean of run - recorded [t/h]", "{:.4g}"),
    "feed_tph_mean_abs_diff": ("feed rate, mean |run - recorded| [t/h]", "{:.4g}"),
    "speed_frac_critical_mean_diff": ("speed, mean of run - recorded [fraction of critical]", "{:.4g}"),
    "speed_frac_critical_mean_abs_diff": ("speed, mean |run - recorded| [fraction of critical]", "{:.4g}"),
    "p80_um_mean_diff": ("P80, mean of run - recorded [µm]", "{:.4g}"),
    "p80_um_mean_abs_diff": ("P80, mean |run - recorded| [µm]", "{:.4g}"),
}
