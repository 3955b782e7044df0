"""Control baselines and evaluation (see the baselines issue)."""
