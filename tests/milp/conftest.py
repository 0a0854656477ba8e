import sys
from pathlib import Path

# the double integrator and random formulas of tests/compiler/milp_systems.py
sys.path.insert(0, str(Path(__file__).parents[1] / "compiler"))
