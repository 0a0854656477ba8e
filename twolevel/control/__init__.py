"""The controllers: ``planner`` (the interface both high-level planners implement, and its
types), ``high_level`` (the MILP MPC), ``nmpc`` (the NMPC baseline), ``registry`` (planners by
name), ``low_level`` (the runtime monitor that checks and corrects a plan), ``codes``."""
