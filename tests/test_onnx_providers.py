"""``onnx.providers``: every ONNX plug-in runs on the configured onnxruntime providers (CUDA
where available by default), and the log line that loads a model names the one it runs on."""

from __future__ import annotations

import logging

import onnxruntime as ort
import pytest
from click.testing import CliRunner

from sr3d_cli.cli import cli
from sr3d_cli.errors import ConfigError
from sr3d_cli import onnx_model
from sr3d_cli.onnx_model import OnnxModel, resolve_providers, use_providers
from tests import onnx_builders
from tests.conftest import make_native_scene

CPU, CUDA = "CPUExecutionProvider", "CUDAExecutionProvider"


def test_automatic_choice_prefers_cuda_then_cpu():
    assert resolve_providers([], [CUDA, CPU]) == [CUDA, CPU]
    assert resolve_providers([], ["AzureExecutionProvider", CPU]) == [CPU]
    assert resolve_providers(["cuda", "cpu"], [CUDA, CPU]) == [CUDA, CPU]
    assert resolve_providers([CPU], [CUDA, CPU]) == [CPU]


def test_a_provider_onnxruntime_lacks_is_named_with_the_install_hint():
    with pytest.raises(ConfigError, match="onnx.providers") as err:
        resolve_providers(["cuda"], [CPU])
    assert CUDA in str(err.value) and "onnxruntime-gpu" in str(err.value)


@pytest.fixture
def sr3d_log():
    """Messages of the 'sr3d' logger at INFO."""
    logger = logging.getLogger("sr3d")
    records: list[str] = []
    handler = logging.Handler()
    handler.emit = lambda record: records.append(record.getMessage())
    old = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    yield records
    logger.removeHandler(handler)
    logger.setLevel(old)
    use_providers([])


def test_models_load_on_the_configured_providers_and_say_so(tmp_path, sr3d_log, monkeypatch):
    path = onnx_builders.sam_encoder(tmp_path / "enc.onnx")
    asked = []
    real = ort.InferenceSession

    def recording(*args, providers=None, **kwargs):
        asked.append(providers)
        return real(*args, providers=[CPU], **kwargs)

    monkeypatch.setattr(ort, "InferenceSession", recording)
    monkeypatch.setattr(ort, "get_available_providers", lambda: [CUDA, CPU])
    OnnxModel(path, "SAM encoder", {"*": None}, {"*": None})
    assert asked[-1] == [CUDA, CPU]  # automatic: CUDA first where onnxruntime has it
    assert f"loaded SAM encoder model {path} on {CPU} (onnx.providers: automatic)" in sr3d_log
    use_providers(["cpu"])
    model = OnnxModel(path, "SAM encoder", {"*": None}, {"*": None})
    assert asked[-1] == [CPU] and model.providers == [CPU]
    assert sr3d_log[-1].endswith(f"on {CPU} (onnx.providers: cpu)")
    monkeypatch.setattr(ort, "get_available_providers", lambda: [CPU])
    use_providers([])
    OnnxModel(path, "SAM encoder", {"*": None}, {"*": None})
    assert asked[-1] == [CPU]


def test_a_model_is_made_on_the_default_providers(tmp_path):
    path = onnx_builders.density_sphere(tmp_path / "grid.onnx")
    model = OnnxModel(path, "reconstruction", {"*": None}, {"*": None})
    expected = CUDA if CUDA in ort.get_available_providers() else CPU
    assert model.providers[0] == expected


def test_the_command_line_refuses_a_missing_provider_before_any_frame(tmp_path, monkeypatch):
    scene = make_native_scene(tmp_path / "scene", 1)
    monkeypatch.setattr(ort, "get_available_providers", lambda: [CPU])
    result = CliRunner().invoke(cli, ["segment", str(scene), "-q", "--set",
                                      "onnx.providers=[cuda]"])
    assert result.exit_code == 2
    assert "onnx.providers" in result.stderr and "onnxruntime-gpu" in result.stderr
    assert not (scene / "masks").exists()
    assert onnx_model._PROVIDERS == []
