"""Model predictive control, estimation and baselines on the grindtwin mill model."""
