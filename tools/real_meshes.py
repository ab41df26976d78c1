"""Real meshes for validation (issue 19): OBJ/PLY files read with trimesh, split into their
connected pieces, the largest pieces kept. No bpy here: decimation is Blender's (see
tools/real_scenes.py), so this module stays importable by plain tests.

The meshes come from the pybullet wheel on PyPI (docs/validation-real.md):

    pip download --no-deps pybullet==3.2.7 -d /work/cache/pybullet
    unzip -o <wheel> 'pybullet_data/bunny.obj' ... -d /work/cache
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MESH_DIR_ENV = "GALERKIN_MESHES"
DEFAULT_MESH_DIR = Path("/work/cache/pybullet_data")
PYBULLET_WHEEL = "pybullet==3.2.7"
# Vertices closer than this (in file units) are one vertex when pieces are found: OBJ files
# duplicate vertices along UV seams, which would otherwise cut one piece into many.
MERGE_DECIMALS = 4


def mesh_dir(explicit: str | os.PathLike | None = None) -> Path:
    """Where the pybullet_data meshes are: `explicit`, $GALERKIN_MESHES, or the default cache."""
    return Path(explicit or os.environ.get(MESH_DIR_ENV) or DEFAULT_MESH_DIR)


def trimesh_module():
    """trimesh, installed on demand into this interpreter (it is pure Python on numpy)."""
    try:
        import trimesh
    except ImportError:
        print("validate_real: installing trimesh (pip) ...", flush=True)
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "trimesh"], check=True)
        import trimesh
    return trimesh


@dataclass
class Mesh:
    """A triangle mesh in file coordinates (float64 vertices, int64 triangles)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray

    def bounds(self) -> np.ndarray:
        return np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def describe(self) -> str:
        lo, hi = self.bounds()
        return (f"{self.name}: {len(self.faces)} triangles, {len(self.vertices)} vertices, bounds "
                f"{np.round(lo, 3).tolist()} .. {np.round(hi, 3).tolist()}")


def load(path: str | os.PathLike) -> Mesh:
    """An OBJ/PLY/STL file as one triangle mesh, vertices as stored (no merging, no reordering)."""
    path = Path(path)
    if not path.exists():
        raise SystemExit(
            f"{path} is missing: fetch the meshes with `pip download --no-deps {PYBULLET_WHEEL}` and unzip "
            f"pybullet_data/ (docs/validation-real.md), or point ${MESH_DIR_ENV} at that folder"
        )
    trimesh = trimesh_module()
    m = trimesh.load(str(path), force="mesh", process=False)
    return Mesh(path.stem, np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))


def welded(mesh: Mesh) -> Mesh:
    """The mesh with coincident vertices (to MERGE_DECIMALS) merged, unused ones dropped, and
    zero-area or two-vertex triangles removed."""
    key = np.round(mesh.vertices, MERGE_DECIMALS)
    _, first, remap = np.unique(key, axis=0, return_index=True, return_inverse=True)
    faces = remap.ravel()[mesh.faces]
    v = mesh.vertices[first]
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    distinct = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    faces = faces[distinct & (area > 1e-12)]
    return compact(Mesh(mesh.name, v, faces))


def compact(mesh: Mesh) -> Mesh:
    """Drops unused vertices, keeping the order of the used ones."""
    used = np.unique(mesh.faces)
    remap = np.full(len(mesh.vertices), -1, np.int64)
    remap[used] = np.arange(len(used))
    return Mesh(mesh.name, mesh.vertices[used], remap[mesh.faces])


def piece_labels(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Connected piece of every triangle (triangles sharing a vertex are one piece): label
    propagation to the smallest vertex index, iterated to a fixed point."""
    parent = np.arange(n_vertices)
    while True:
        roots = parent[faces]
        low = roots.min(axis=1)
        for k in range(3):
            np.minimum.at(parent, roots[:, k], low)
        while True:  # path compression: every vertex points at its root
            up = parent[parent]
            if (up == parent).all():
                break
            parent = up
        roots = parent[faces]
        if (roots.min(axis=1) == roots.max(axis=1)).all():
            return roots[:, 0]


def triangle_areas(mesh: Mesh) -> np.ndarray:
    v, f = mesh.vertices, mesh.faces
    return 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)


def largest_pieces(mesh: Mesh, max_faces: int) -> tuple[Mesh, int, int]:
    """The pieces of largest area (ties: more faces, then lower label: deterministic), taken in
    that order while their faces total at most `max_faces`. Returns (mesh, pieces kept, pieces)."""
    labels = piece_labels(mesh.faces, len(mesh.vertices))
    uniq, inv, counts = np.unique(labels, return_inverse=True, return_counts=True)
    area = np.bincount(inv, weights=triangle_areas(mesh))
    order = np.lexsort((uniq, -counts, -area))
    keep, total = [], 0
    for p in order:
        if total + counts[p] > max_faces:
            continue
        keep.append(p)
        total += counts[p]
    mask = np.isin(inv, keep)
    return compact(Mesh(mesh.name, mesh.vertices, mesh.faces[mask])), len(keep), len(uniq)


def is_closed(mesh: Mesh) -> bool:
    """Every edge is shared by exactly two triangles, in opposite directions (closed, oriented)."""
    f = mesh.faces
    edges = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    directed, counts = np.unique(edges, axis=0, return_counts=True)
    if (counts != 1).any():
        return False
    flipped = {tuple(e) for e in directed[:, ::-1]}
    return all(tuple(e) in flipped for e in directed)
