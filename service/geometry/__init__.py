"""Geometry: robot paths and footprints -> where they interfere -> a coordination graph."""
