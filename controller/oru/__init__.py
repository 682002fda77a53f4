"""The ORU changeout task flow (ORU paper Section 2, Table 1): config, steps, runner."""
