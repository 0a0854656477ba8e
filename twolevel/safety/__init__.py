"""Online verification: the ego is never at fault, whatever the planner above the low level.

(Full statement of the guarantee below, once the modules exist.)
"""
