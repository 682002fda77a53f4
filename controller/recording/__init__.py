"""Recording of runs: MCAP (Foxglove/PlotJuggler), a raw CAN trace, and CSV export."""
