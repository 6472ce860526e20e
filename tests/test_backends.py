"""Backends are chosen by name through one registry per config key."""

from __future__ import annotations

import pytest

from sr3d_cli.backends import RECONSTRUCT, REGISTRIES, RENDER, SEGMENT
from sr3d_cli.config import CHOICES, PlaneConfig, ReconstructConfig, SegmentConfig, build_config
from sr3d_cli.errors import ConfigError


@pytest.mark.parametrize("registry", REGISTRIES, ids=lambda r: r.key)
def test_every_registered_name_is_a_factory_and_the_config_accepts_exactly_these(registry):
    for name in registry.names:
        assert callable(registry.factory(name)), name
    assert CHOICES[registry.key] == registry.names
    with pytest.raises(ConfigError, match=", ".join(registry.names)):
        build_config(None, [f"{registry.key}=nope"])


def test_an_unknown_name_is_refused_listing_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown segment.backend 'nope' \(known: "
                                         r"training-free, sam-onnx, import\)"):
        SEGMENT.create("nope", SegmentConfig(), PlaneConfig())
    from sr3d_cli.render import make_renderer

    with pytest.raises(ValueError, match="unknown render.backend 'gl'"):
        make_renderer("gl")


def test_the_stage_objects_build_the_configured_backend():
    from sr3d_cli.reconstruct import LibraryBackend, Reconstructor, RevolutionBackend
    from sr3d_cli.render import NumpyRenderer, make_renderer
    from sr3d_cli.segment import Imported, Segmenter, TrainingFree

    assert isinstance(make_renderer("numpy"), NumpyRenderer)
    assert make_renderer("numpy") is make_renderer("numpy")  # one per process
    assert isinstance(Segmenter(SegmentConfig(), PlaneConfig()).backend, TrainingFree)
    assert isinstance(Segmenter(SegmentConfig(backend="import"), PlaneConfig()).backend,
                      Imported)
    revolution = Reconstructor(ReconstructConfig())
    assert type(revolution.backend) is RevolutionBackend and revolution.needs_plane
    assert RECONSTRUCT.factory("library") is LibraryBackend
    assert RENDER.factory("numpy") is NumpyRenderer
