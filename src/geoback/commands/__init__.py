"""Commands: the command line and what each command does end to end (run, simulate, validate, batch,
init)."""
