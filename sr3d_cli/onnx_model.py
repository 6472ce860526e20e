"""Loading user-supplied ONNX models with their tensor names and shapes checked up front.

Every learned model in sr3d is an optional plug-in: a file the user brings. A model whose inputs
or outputs differ from what a backend needs fails once, at load time, with one message listing
what was expected and what was found.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

from sr3d_cli.errors import InputError

Shape = Sequence[int | None]  # None: any size (dynamic axis)


def _fmt(tensors) -> str:
    return ", ".join(f"{t.name} {list(t.shape)}" for t in tensors) or "none"


def _shape_ok(found, wanted: Shape | None) -> bool:
    if wanted is None:
        return True
    if len(found) != len(wanted):
        return False
    return all(w is None or not isinstance(f, int) or f == w for f, w in zip(found, wanted))


class OnnxModel:
    """An onnxruntime session on the CPU whose tensors were checked.

    inputs / outputs : {name: shape}; a name of ``"*"`` means "the only tensor, whatever its name"
    (encoders are exported with many different input names).
    """

    def __init__(self, path: str | Path, role: str, inputs: Mapping[str, Shape | None],
                 outputs: Mapping[str, Shape | None]):
        self.path = Path(path)
        if not str(path):
            raise InputError(path, f"no {role} model given (set its path in the config)")
        if not self.path.is_file():
            raise InputError(self.path, f"{role} model file not found")
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(self.path), options,
                                                providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types
            raise InputError(self.path, f"not a loadable ONNX {role} model "
                                        f"({str(exc).splitlines()[0][:200]})") from None
        self.input_names = self._check("input", self.session.get_inputs(), inputs, role)
        self.output_names = self._check("output", self.session.get_outputs(), outputs, role)

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
        values = self.session.run([self.output_names[k] for k in wanted], real)
        return dict(zip(wanted, values))
