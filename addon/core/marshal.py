"""Meshes to the arrays of ``binding.Session``, and digests used to notice what changed.

A mesh arrives as Blender stores it (object-space vertices, polygon sizes, loop vertex indices,
polygon material indices mapped to library materials) and leaves as library faces (see
``polygons.split_faces``), with the world-from-object matrix row-major as ``np.array(matrix_world)``.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from .polygons import FaceSplit, degenerate_faces, split_faces

MATRIX_DECIMALS = 6
VERTEX_DECIMALS = 6


def digest(*arrays, decimals: int | None = None) -> str:
    """A short stable digest of arrays (rounded to `decimals` first, if given)."""
    h = hashlib.sha1()
    for a in arrays:
        a = np.asarray(a)
        if decimals is not None and a.dtype.kind == "f":
            a = np.round(a.astype(np.float64), decimals) + 0.0  # + 0.0 folds -0.0 into 0.0
        h.update(str(a.shape).encode())
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


@dataclass
class ObjectData:
    """One object as the library sees it, plus what maps results back."""

    name: str
    vertices: np.ndarray        # (N,3) float32, object space
    split: FaceSplit
    face_materials: np.ndarray  # (F',) uint32, per library face
    matrix: np.ndarray          # (4,4) float64, world-from-object, row-major
    polygon_count: int
    degenerate: np.ndarray      # library faces of zero area
    corner_normals: np.ndarray | None = None     # (C', 3) float32 per library corner; zero: flat
    face_reflectance: np.ndarray | None = None   # (F', 3) float32 per library face (textures)
    face_emission: np.ndarray | None = None      # (F', 3) float32 emission scale per library face

    @classmethod
    def from_mesh(cls, name, vertices, polygon_sizes, loop_vertices, polygon_materials, matrix,
                  split: FaceSplit | None = None) -> ObjectData:
        """`polygon_materials` are library material indices per polygon. `split`: the library
        faces of another frame's export of the same mesh (a deformed frame's rebuild), kept where
        they fit its loops, so that a quad bending or unbending does not change the faces."""
        vertices = np.asarray(vertices, np.float32).reshape(-1, 3)
        sizes = np.asarray(polygon_sizes, np.int64)
        loops = np.asarray(loop_vertices, np.int64)
        if split is None or not split.fits(sizes, loops):
            split = split_faces(vertices, sizes, loops)
        mats = np.asarray(polygon_materials, np.int64)[split.source_face].astype(np.uint32)
        return cls(
            name=name,
            vertices=vertices,
            split=split,
            face_materials=mats,
            matrix=np.asarray(matrix, np.float64).reshape(4, 4),
            polygon_count=len(sizes),
            degenerate=degenerate_faces(vertices, split.face_sizes, split.face_indices),
        )

    def set_loop_normals(self, loop_normals, polygon_normals) -> None:
        """Smooth shading: the mesh's normal per loop (``Mesh.corner_normals``, custom split
        normals included) as the library's corner normals. A corner whose normal is its polygon's
        (a flat face) gets the zero vector, the library's "the face's own normal", so flat faces
        are gathered exactly as without normals; none at all when every corner is flat."""
        loop_normals = np.asarray(loop_normals, np.float32).reshape(-1, 3)
        polygon_normals = np.asarray(polygon_normals, np.float32).reshape(-1, 3)
        corner = loop_normals[self.split.corner_loop]
        face = polygon_normals[self.split.source_face]
        per_corner_face = np.repeat(face, self.split.face_sizes.astype(np.int64), axis=0)
        flat = np.all(np.abs(corner - per_corner_face) <= 1e-6, axis=1)
        if flat.all():
            self.corner_normals = None
            return
        corner = corner.copy()
        corner[flat] = 0.0
        self.corner_normals = corner

    def set_polygon_reflectance(self, polygon_rho) -> None:
        """Reflectance per mesh polygon (a texture's mean over it) as the library's per face."""
        self.face_reflectance = np.asarray(polygon_rho, np.float32).reshape(-1, 3)[self.split.source_face]

    def set_polygon_emission(self, polygon_scale) -> None:
        """Emission colour scale per mesh polygon (an emission texture's mean over it, multiplying
        its material's emission) as the library's per face."""
        self.face_emission = np.asarray(polygon_scale, np.float32).reshape(-1, 3)[self.split.source_face]

    @property
    def loop_count(self) -> int:
        return self.split.n_loops

    def native(self) -> dict:
        """The object dict of ``binding.Session``."""
        return {
            "vertices": self.vertices,
            "face_sizes": self.split.face_sizes,
            "face_indices": self.split.face_indices,
            "face_materials": self.face_materials,
            "matrix": self.matrix,
            "corner_normals": self.corner_normals,
            "face_reflectance": self.face_reflectance,
            "face_emission": self.face_emission,
        }

    def topology_key(self) -> str:
        """Changes when faces, corners or materials change (not when vertices move)."""
        extra = [a for a in (self.corner_normals, self.face_reflectance) if a is not None]
        if self.face_emission is not None:
            # Tagged, so that the same values as an emission scale or a reflectance differ.
            extra += [np.frombuffer(b"face_emission", np.uint8), self.face_emission]
        return digest(self.split.face_sizes, self.split.face_indices, self.face_materials, *extra, decimals=6)

    def geometry_key(self) -> str:
        """Changes when the object-space vertices move (deformation)."""
        return digest(self.vertices, decimals=VERTEX_DECIMALS)

    def matrix_key(self) -> str:
        return digest(self.matrix, decimals=MATRIX_DECIMALS)


def emission_key(emission: np.ndarray) -> str:
    return digest(np.asarray(emission, np.float64), decimals=6)


def with_object_names(line: str, names: list[str]) -> str:
    """A library message with its ``"object N"`` (how the C ABI names objects) replaced by the
    Blender names, in library order."""
    import re

    def name(m):
        i = int(m.group(1))
        return f'"{names[i]}"' if i < len(names) else m.group(0)

    return re.sub(r'"object (\d+)"', name, line)
