"""The controller daemon: cycle clock, supervision, modes, command API, recording."""
