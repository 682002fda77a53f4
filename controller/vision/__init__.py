"""The vision pipeline: circle detection, marker labelling, PnP, the vision worker."""
