"""Input layouts read in place, and the discovery of scene folders below a path.

Each layout is a :class:`~sr3d_cli.io.scene.SceneSource` subclass with a ``looks_like(folder)``
test; :data:`LAYOUTS` is the registry ``--format`` chooses from.
"""

from __future__ import annotations

from pathlib import Path

from sr3d_cli.config import IOConfig
from sr3d_cli.errors import InputError
from sr3d_cli.io.formats.bop import BOPSource
from sr3d_cli.io.formats.cleargrasp import ClearGraspSource
from sr3d_cli.io.formats.transcg import TransCGSource
from sr3d_cli.io.scene import SceneSource


def _native_looks_like(folder: Path) -> bool:
    return (folder / "rgb").is_dir() and (folder / "depth").is_dir() and \
        not (folder / "scene_camera.json").is_file()


LAYOUTS: dict[str, tuple[type[SceneSource], object]] = {
    "native": (SceneSource, _native_looks_like),
    "cleargrasp": (ClearGraspSource, ClearGraspSource.looks_like),
    "transcg": (TransCGSource, TransCGSource.looks_like),
    "bop": (BOPSource, BOPSource.looks_like),
}

MAX_DEPTH = 4  # how deep below the given path scene folders are searched


def detect_layout(folder: Path) -> str | None:
    for name, (_, looks_like) in LAYOUTS.items():
        if looks_like(folder):
            return name
    return None


def discover_scenes(path: str | Path, io: IOConfig, out: str | Path | None = None
                    ) -> list[SceneSource]:
    """Scene folders at or below ``path`` (sorted), each as a :class:`SceneSource`.

    ``out`` is the output root (default: ``path``); a scene at ``path/a/b`` writes to
    ``out/a/b``. Raises :class:`InputError` when nothing is found.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "does not exist")
    if not path.is_dir():
        raise InputError(path, "is not a folder")
    out_root = Path(out) if out is not None else path
    found: list[tuple[Path, str]] = []

    def walk(folder: Path, level: int) -> None:
        layout = io.format if io.format != "auto" else detect_layout(folder)
        if layout is not None and LAYOUTS[layout][1](folder):
            found.append((folder, layout))
            return
        if level >= MAX_DEPTH:
            return
        for child in sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")):
            walk(child, level + 1)

    walk(path, 0)
    if not found:
        wanted = "scene folder" if io.format == "auto" else f"{io.format} scene folder"
        raise InputError(path, f"no {wanted} found here or below (native: rgb/ and depth/ "
                               "folders; ClearGrasp: NNN-transparent-rgb-img.jpg files; TransCG: "
                               "<view>/rgb1.png; BOP: scene_camera.json)")
    scenes = []
    for folder, layout in found:
        rel = folder.relative_to(path)
        name = "" if rel == Path(".") else rel.as_posix()
        cls = LAYOUTS[layout][0]
        if hasattr(cls, "expand"):  # one folder, several cameras
            scenes += cls.expand(folder, out_root / rel, name, io)
        else:
            scenes.append(cls(folder, out=out_root / rel, name=name, io=io))
    return scenes


def describe(scenes: list[SceneSource]) -> str:
    """What auto-detection found, e.g. ``2 scenes: transcg x2``."""
    counts: dict[str, int] = {}
    for s in scenes:
        counts[s.layout] = counts.get(s.layout, 0) + 1
    return f"{len(scenes)} scene{'s' if len(scenes) != 1 else ''}: " + ", ".join(
        f"{k} x{v}" for k, v in counts.items())
