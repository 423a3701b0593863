"""Simulation: a kinematic executor of dependency plans, disturbances, and the clearance check."""
