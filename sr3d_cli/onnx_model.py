"""Loading user-supplied ONNX models with their tensor names and shapes checked up front.

Every learned model in sr3d is an optional plug-in: a file the user brings. A model whose inputs
or outputs differ from what a backend needs fails once, at load time, with one message listing
what was expected and what was found.

Execution providers (config ``onnx.providers``) are the same for every plug-in: the command line
sets them once with :func:`use_providers`; ``[]`` means CUDA where this onnxruntime has it, else
the CPU. The log line that loads a model names the provider that runs it.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Mapping, Sequence

from sr3d_cli.errors import ConfigError, InputError

log = logging.getLogger("sr3d")

Shape = Sequence[int | None]  # None: any size (dynamic axis)


def _fmt(tensors) -> str:
    return ", ".join(f"{t.name} {list(t.shape)}" for t in tensors) or "none"


def _shape_ok(found, wanted: Shape | None) -> bool:
    if wanted is None:
        return True
    if len(found) != len(wanted):
        return False
    return all(w is None or not isinstance(f, int) or f == w for f, w in zip(found, wanted))


ALIASES = {"cpu": "CPUExecutionProvider", "cuda": "CUDAExecutionProvider",
           "tensorrt": "TensorrtExecutionProvider", "rocm": "ROCMExecutionProvider",
           "coreml": "CoreMLExecutionProvider", "dml": "DmlExecutionProvider",
           "openvino": "OpenVINOExecutionProvider"}
GPU_HINT = "pip install onnxruntime-gpu (in place of onnxruntime) for CUDA"
_PROVIDERS: list[str] = []  # as configured (onnx.providers); [] = automatic


def use_providers(names: Sequence[str]) -> None:
    """Set the execution providers of every model loaded afterwards (``[]``: automatic)."""
    _PROVIDERS[:] = list(names)


def resolve_providers(names: Sequence[str], available: Sequence[str]) -> list[str]:
    """Provider names for onnxruntime: aliases (``cuda``, ``cpu``, ...) expanded; ``[]`` gives
    CUDA then CPU where CUDA is available, else CPU. Raises :class:`ConfigError` naming
    ``onnx.providers`` for a provider this onnxruntime does not have."""
    if not names:
        return (["CUDAExecutionProvider", "CPUExecutionProvider"]
                if "CUDAExecutionProvider" in available else ["CPUExecutionProvider"])
    full = [ALIASES.get(n.lower(), n) for n in names]
    missing = [n for n in full if n not in available]
    if missing:
        hint = f"; {GPU_HINT}" if "CUDAExecutionProvider" in missing else ""
        raise ConfigError(f"'onnx.providers': {', '.join(missing)} not available in this "
                          f"onnxruntime (available: {', '.join(available)}){hint}")
    return full


class OnnxModel:
    """An onnxruntime model whose tensors were checked, run on the configured providers.

    inputs / outputs : {name: shape}; a name of ``"*"`` means "the only tensor, whatever its name"
    (encoders are exported with many different input names). ``providers``: this model's
    execution providers (default: those set by :func:`use_providers`).
    """

    def __init__(self, path: str | Path, role: str, inputs: Mapping[str, Shape | None],
                 outputs: Mapping[str, Shape | None], providers: Sequence[str] | None = None):
        self.path = Path(path)
        if not str(path):
            raise InputError(path, f"no {role} model given (set its path in the config)")
        if not self.path.is_file():
            raise InputError(self.path, f"{role} model file not found")
        import onnxruntime as ort

        asked = list(_PROVIDERS if providers is None else providers)
        chosen = resolve_providers(asked, ort.get_available_providers())
        options = ort.SessionOptions()
        options.log_severity_level = 3
        try:
            self.runtime = ort.InferenceSession(str(self.path), options, providers=chosen)
        except Exception as exc:  # onnxruntime raises its own exception types
            raise InputError(self.path, f"not a loadable ONNX {role} model "
                                        f"({str(exc).splitlines()[0][:200]})") from None
        self.providers = list(self.runtime.get_providers())
        log.info("loaded %s model %s on %s (onnx.providers: %s)", role, self.path,
                 self.providers[0] if self.providers else "?",
                 ", ".join(asked) if asked else "automatic")
        self.input_names = self._check("input", self.runtime.get_inputs(), inputs, role)
        self.output_names = self._check("output", self.runtime.get_outputs(), outputs, role)

    def _check(self, kind, found, wanted, role) -> dict[str, str]:
        by_name = {t.name: t for t in found}
        names, problems = {}, []
        for name, shape in wanted.items():
            if name == "*":
                tensor = found[0] if len(found) == 1 else None
            else:
                tensor = by_name.get(name)
            if tensor is None or not _shape_ok(tensor.shape, shape):
                problems.append(name)
            else:
                names[name] = tensor.name
        if problems:
            want = ", ".join(f"{n if n != '*' else '(one tensor)'} "
                             f"{['?' if d is None else d for d in s] if s is not None else ''}"
                             for n, s in wanted.items())
            raise InputError(self.path, f"{role} model {kind}s do not match: expected {want}; "
                                        f"found {_fmt(found)}")
        return names

    def run(self, feeds: Mapping[str, object]) -> dict[str, object]:
        """Run with ``feeds`` keyed by the wanted names; returns outputs keyed the same way."""
        real = {self.input_names[k]: v for k, v in feeds.items()}
        wanted = list(self.output_names)
        values = self.runtime.run([self.output_names[k] for k in wanted], real)
        return dict(zip(wanted, values))
