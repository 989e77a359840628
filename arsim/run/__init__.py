"""`arsim run`: a scenario end to end into a run directory, with its report and manifest."""
