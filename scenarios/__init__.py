"""Scenes, replays, what-if sweeps, reports and the grindtwin command."""
