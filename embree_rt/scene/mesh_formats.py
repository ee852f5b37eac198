"""Which files are mesh files: their suffixes, known without importing trimesh (which reads
them, and takes most of a second to import), so that a command tells a mesh file from a scene
or particle file before it decides what to load."""

from __future__ import annotations

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
