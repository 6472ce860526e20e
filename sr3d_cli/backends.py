"""Backends by name: each registry maps the names one config key accepts to the factory that
builds that backend.

A factory is written as ``"module:attribute"`` and imported only when a backend is built, so the
config can check a name, and the command line offer the names, without loading any backend (nor
its models). Adding a backend is one entry here and its class; nothing else chooses by name.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Callable, Mapping


@dataclass(frozen=True)
class Registry:
    key: str  # the config key whose value names the backend, e.g. "segment.backend"
    factories: Mapping[str, str]  # name -> "module:attribute" of the factory

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.factories)

    def factory(self, name: str) -> Callable[..., Any]:
        """The factory registered as ``name``; ValueError listing the known names otherwise."""
        if name not in self.factories:
            raise ValueError(f"unknown {self.key} {name!r} (known: {', '.join(self.names)})")
        module, _, attribute = self.factories[name].partition(":")
        return getattr(importlib.import_module(module), attribute)

    def create(self, name: str, *args: Any, **kwargs: Any) -> Any:
        """The backend ``name`` built with ``args`` and ``kwargs``."""
        return self.factory(name)(*args, **kwargs)


RENDER = Registry("render.backend", {
    "auto": "sr3d_cli.render:auto_renderer",
    "pyrender": "sr3d_cli.render:PyrenderRenderer",
    "numpy": "sr3d_cli.render:NumpyRenderer",
})
SEGMENT = Registry("segment.backend", {
    "training-free": "sr3d_cli.segment:TrainingFree",
    "sam-onnx": "sr3d_cli.segment:SamPrompted",
    "import": "sr3d_cli.segment:Imported",
})
RECONSTRUCT = Registry("reconstruct.backend", {
    "revolution": "sr3d_cli.reconstruct:RevolutionBackend",
    "onnx": "sr3d_cli.reconstruct:OnnxBackend",
    "library": "sr3d_cli.reconstruct:LibraryBackend",
})
REGISTRIES = (RENDER, SEGMENT, RECONSTRUCT)
