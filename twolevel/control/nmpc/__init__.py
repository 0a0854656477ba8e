"""The NMPC baseline the paper compares against: ``controller`` (the planner) and ``nlp`` (the
nonlinear program, casadi + IPOPT). Import from the modules; this package imports nothing."""
