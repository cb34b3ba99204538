"""Session fixtures for the planners tests (meshes built in navmesh_meshes.py)."""

from __future__ import annotations

import pytest
from navmesh_meshes import bake, l_floor, room_with_pillars

from planners import NavMesh


@pytest.fixture(scope="session")
def room_nm() -> NavMesh:
    return bake(room_with_pillars())


@pytest.fixture(scope="session")
def l_nm() -> NavMesh:
    return bake(l_floor())
