"""The operator console in the browser (ORU paper Section 3.4, Figure 11): a local web
server that is one more client of the daemon's command API, a 3-D scene with presimulation,
live state and the camera monitor. Started by `spacearm console-web`."""
