"""Vectorised P1 finite-element kernels over tetrahedral meshes."""
