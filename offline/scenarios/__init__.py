"""Scripted operations run through the daemon's command handlers, as a console would."""
