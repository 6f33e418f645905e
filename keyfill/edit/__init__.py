"""Tangent-space editing of Bezier animation curves (Ciccone et al. 2019)."""
