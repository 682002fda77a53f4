"""Sim-vs-real diagnosis: locate where a recording departs from the nominal simulation,
name the missing physical effect, fit it, and show the fit improve on held-out data."""
