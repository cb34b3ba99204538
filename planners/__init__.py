"""Navmesh baking, exact shortest paths, geodesic distance fields, motion on the surface.

`NavMesh.bake(trimesh_mesh, NavMeshSettings(...))` follows Recast's voxel rules (slope, climb,
headroom, ledges, erosion by the agent radius, minimum island area) and triangulates the result;
queries follow Habitat's PathFinder names and take/return points in the mesh's own scene frame.
"""

from planners.fields import GeodesicField
from planners.navmesh import IslandInfo, NavMesh
from planners.path import PathResult
from planners.raster import GeodesicRaster
from planners.settings import NavMeshFileError, NavMeshSettings, OffMeshError

__all__ = ["NavMesh", "NavMeshSettings", "PathResult", "OffMeshError", "NavMeshFileError", "GeodesicField",
           "GeodesicRaster", "IslandInfo"]
