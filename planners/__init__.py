"""Navmesh baking, exact shortest paths, geodesic distance fields, motion on the surface."""
