"""A folder of meshes (CAD models or meshes made offline) to pick from.

An entry is chosen by label (the instance label contains the file stem, or the other way round)
or, failing that, as the entry whose outer profile is closest to the training-free fit of the
object's silhouette. Entries are normalised into the object frame when loaded.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree

from sr3d_cli.errors import InputError
from sr3d_cli.geometry.revolution import profile_from_mesh

SUFFIXES = (".ply", ".obj", ".stl", ".glb", ".off")


def _profile_points(profile: np.ndarray, n: int = 200) -> np.ndarray:
    """Evenly spaced points along a profile polyline ``(k, 2)``."""
    seg = np.linalg.norm(np.diff(profile, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    t = np.linspace(0, s[-1], n)
    return np.column_stack([np.interp(t, s, profile[:, 0]), np.interp(t, s, profile[:, 1])])


class MeshLibrary:
    def __init__(self, folder: str):
        from sr3d_cli.reconstruct import normalise_mesh

        self.folder = Path(folder)
        if not str(folder) or not self.folder.is_dir():
            raise InputError(self.folder, "mesh library folder not found (reconstruct.library)")
        self.meshes: dict[str, trimesh.Trimesh] = {}
        for path in sorted(self.folder.iterdir()):
            if path.suffix.lower() not in SUFFIXES:
                continue
            try:
                mesh = trimesh.load(path, force="mesh", process=True)
                self.meshes[path.stem] = normalise_mesh(mesh)
            except Exception as exc:
                raise InputError(path, f"cannot load library mesh ({exc})") from None
        if not self.meshes:
            raise InputError(self.folder, f"no meshes ({', '.join(SUFFIXES)}) in the library")
        self.profiles = {k: _profile_points(profile_from_mesh(m)) for k, m in self.meshes.items()}

    def pick(self, label: str, profile: np.ndarray) -> tuple[str, trimesh.Trimesh]:
        """(name, mesh) matching ``label``, else closest in profile to ``profile`` (r, z)."""
        words = label.lower()
        for name in self.meshes:
            if name.lower() in words or (words and words in name.lower()):
                return name, self.meshes[name]
        target = _profile_points(profile)
        tree = cKDTree(target)

        def distance(name: str) -> float:
            pts = self.profiles[name]
            return float(tree.query(pts)[0].mean() + cKDTree(pts).query(target)[0].mean())

        best = min(self.meshes, key=distance)
        return best, self.meshes[best]
