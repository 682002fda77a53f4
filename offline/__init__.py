"""Tools that drive the simulator and the controller together: sim-vs-real diagnosis, contact trials, scenarios."""
