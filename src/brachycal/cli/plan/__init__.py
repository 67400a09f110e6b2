"""brachycal plan: the grid (default), plan check, plan excitation."""
