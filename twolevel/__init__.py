"""twolevel: provably-correct two-level control for autonomous driving from STL traffic rules.

Implements and extends Aasi, Vasile, Belta, "A Control Architecture for Provably-Correct
Autonomous Driving" (arXiv 2105.02759). See README.md and the architecture in docs.
"""

__version__ = "0.1.0"
