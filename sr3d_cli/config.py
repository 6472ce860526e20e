"""One configuration for every stage: dataclasses with defaults, YAML files, ``--set`` overrides.

Precedence, lowest first: built-in defaults < YAML file < ``--set section.key=value`` < explicit
command-line flags. Unknown sections or keys and values of the wrong type raise
:class:`~sr3d_cli.errors.ConfigError` naming the key and where it came from.

Which keys a user sees: a key is user-facing when it picks a backend or a model file, describes
the hardware (camera and depth I/O, the gripper, friction), chooses inputs, outputs or how to
evaluate, or is a threshold a user sets for their scenes (such as ``segment.min_score``); every
other key is a tuning constant of an algorithm, listed in :data:`ADVANCED`. The YAML layout
(:func:`to_layout`, ``configs/default.yaml``) keeps the tuning constants apart, in an
``advanced:`` section of ``{section: {key: value}}``; they are set there or with ``--set
advanced.section.key=value``, and ``section.key`` names them too. Either way they land on the same
dataclass field (``cfg.segment.close_radius``), so the code and the stage outputs' provenance
records know every key by ``section.key``. ``configs/default.yaml`` lists every key with a
comment; a test keeps it equal to these defaults.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

from sr3d_cli.backends import REGISTRIES
from sr3d_cli.errors import ConfigError


@dataclass
class IOConfig:
    format: str = "auto"
    camera: str = ""
    depth_scale: float = 0.001
    min_median_depth: float = 0.05
    max_median_depth: float = 20.0


@dataclass
class OnnxConfig:
    providers: list[str] = field(default_factory=list)  # [] = CUDA where available, else CPU


@dataclass
class RenderConfig:
    backend: str = "auto"


@dataclass
class PlaneConfig:
    threshold: float = 0.006
    iterations: int = 300
    min_share: float = 0.15


@dataclass
class SegmentConfig:
    backend: str = "training-free"
    prompt: str = ""
    min_area: int = 150
    close_radius: int = 6
    rough_factor: float = 2.0
    grabcut_iterations: int = 4
    max_object_share: float = 0.25
    stereo_baseline: float = 0.05
    min_score: float = 0.3
    import_dir: str = ""
    sam_encoder: str = ""
    sam_decoder: str = ""
    boxes: str = ""
    points: str = ""


@dataclass
class ReconstructConfig:
    backend: str = "revolution"
    masks: str = "segment"
    min_pixels: int = 100
    allow_border: bool = True
    levels: int = 40
    iterations: int = 12
    sections: int = 48
    lying_margin: float = 0.03
    use_depth: bool = True
    depth_vote: float = 2.0
    axial_view: float = 25.0
    smooth: float = 1.0
    straight_wall: float = 2.0
    open_top_ratio: float = 0.7
    open_wall: float = 0.0025
    open_base: float = 0.008
    open_explains: float = 0.5
    onnx_model: str = ""
    onnx_decoder: str = ""
    onnx_threshold: float = 25.0
    onnx_resolution: int = 64
    onnx_radius: float = 0.87
    foreground_ratio: float = 0.85
    library: str = ""


@dataclass
class AlignConfig:
    mode: str = "sr3d"
    views: int = 162
    rolls: int = 12
    yaw_steps: int = 36
    max_rests: int = 6
    alpha: float = 0.5
    beta: float = 0.3
    gamma: float = 0.2
    patches: int = 4
    contact_points: int = 30
    top_candidates: int = 3
    upright_prior: float = 0.05
    hint_accept: float = 0.75
    refine: bool = True
    refine_evals: int = 80
    refine_hint: bool = False
    use_depth: bool = True
    depth_inlier: float = 0.01
    depth_quantile: float = 0.35
    depth_min_share: float = 0.05
    depth_min_points: int = 30
    depth_samples: int = 400
    depth_max_change: float = 0.03
    depth_search: float = 0.25
    depth_vote: float = 2.0
    depth_agree: float = 0.5
    window: int = 160


@dataclass
class RepairConfig:
    outside_render: str = "nearest"
    beyond_mask: bool = True
    keep_nearer: bool = True


@dataclass
class GraspConfig:
    source: str = "repaired"
    max_width: float = 0.08
    finger_length: float = 0.05
    finger_thickness: float = 0.01
    finger_height: float = 0.02
    palm_width: float = 0.2
    palm_height: float = 0.06
    palm_depth: float = 0.06
    base_to_tip: float = 0.1034
    depths: list[float] = field(default_factory=lambda: [0.005, 0.01, 0.02, 0.03, 0.04])
    friction: float = 0.5
    width_margin: float = 0.004
    open_wide: bool = True
    clearance: float = 0.003
    seeds: int = 80
    seed_bins: int = 12
    seed: int = 0
    redraws: int = 6
    height_tolerance: float = 0.004
    tilt_tolerance: float = 4.0
    approaches: int = 5
    pair_radius: float = 0.004
    contact_band: float = 0.002
    collision_points: int = 3
    collision_margin: float = 0.003
    tight_margins: float = 0.5
    fallback_friction: float = 2.0
    mesh_points: int = 2400
    stride: int = 3
    nms_distance: float = 0.03
    nms_angle: float = 30.0
    top_k: int = 10
    friction_weight: float = 0.48
    width_weight: float = 0.16
    approach_weight: float = 0.16
    centre_weight: float = 0.2
    run_scale: float = 0.02
    junction_drop: float = 0.01
    end_weight: float = 0.2
    end_band: float = 0.005


@dataclass
class SynthConfig:
    scenes: int = 4
    views: int = 1
    seed: int = 0
    resolutions: list[str] = field(default_factory=lambda: ["640x480", "848x480"])
    objects: list[int] = field(default_factory=lambda: [1, 3])
    distractors: list[int] = field(default_factory=lambda: [0, 2])
    distance: list[float] = field(default_factory=lambda: [0.35, 0.9])
    elevation_deg: list[float] = field(default_factory=lambda: [25.0, 75.0])
    lying_fraction: float = 0.3
    depth_scale: float = 0.001
    hole_fraction: list[float] = field(default_factory=lambda: [0.05, 0.6])
    see_through_fraction: list[float] = field(default_factory=lambda: [0.1, 0.7])
    noise_opaque: float = 0.0015
    noise_glass: float = 0.004
    max_range: float = 3.0


@dataclass
class EvaluateConfig:
    pred: list[str] = field(default_factory=lambda: ["repaired"])
    holes: str = "full"
    mask: str = "auto"
    plot: bool = False
    plot_max_error: float = 0.05
    protocol: str = "native"
    resolution: str = ""


@dataclass
class Config:
    io: IOConfig = field(default_factory=IOConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    onnx: OnnxConfig = field(default_factory=OnnxConfig)
    plane: PlaneConfig = field(default_factory=PlaneConfig)
    segment: SegmentConfig = field(default_factory=SegmentConfig)
    reconstruct: ReconstructConfig = field(default_factory=ReconstructConfig)
    align: AlignConfig = field(default_factory=AlignConfig)
    repair: RepairConfig = field(default_factory=RepairConfig)
    grasp: GraspConfig = field(default_factory=GraspConfig)
    synth: SynthConfig = field(default_factory=SynthConfig)
    evaluate: EvaluateConfig = field(default_factory=EvaluateConfig)


ADVANCED_SECTION = "advanced"
# the tuning constants of each section (see the module docstring); every other key is user-facing
ADVANCED: dict[str, tuple[str, ...]] = {
    "plane": ("threshold", "iterations", "min_share"),
    "segment": ("close_radius", "rough_factor", "grabcut_iterations", "max_object_share",
                "stereo_baseline"),
    "reconstruct": ("levels", "iterations", "sections", "lying_margin", "use_depth", "depth_vote",
                    "axial_view", "smooth", "straight_wall", "open_top_ratio", "open_wall",
                    "open_base", "open_explains"),
    "align": ("views", "rolls", "yaw_steps", "max_rests", "alpha", "beta", "gamma", "patches",
              "contact_points", "top_candidates", "upright_prior", "hint_accept", "refine",
              "refine_evals", "refine_hint", "use_depth", "depth_inlier", "depth_quantile",
              "depth_min_share", "depth_min_points", "depth_samples", "depth_max_change",
              "depth_search", "depth_vote", "depth_agree", "window"),
    "grasp": ("depths", "seed_bins", "redraws", "height_tolerance", "tilt_tolerance",
              "approaches", "pair_radius", "contact_band", "collision_points",
              "collision_margin", "tight_margins", "fallback_friction", "mesh_points", "stride",
              "nms_distance", "nms_angle", "friction_weight", "width_weight", "approach_weight",
              "centre_weight", "run_scale", "junction_drop", "end_weight", "end_band"),
}


def is_advanced(section: str, key: str) -> bool:
    return key in ADVANCED.get(section, ())


CHOICES: dict[str, tuple[str, ...]] = {
    "io.format": ("auto", "native", "cleargrasp", "transcg", "bop"),
    **{registry.key: registry.names for registry in REGISTRIES},
    "align.mode": ("sr3d", "paper"),
    "repair.outside_render": ("nearest", "keep", "plane"),
    "grasp.source": ("repaired", "raw"),
    "evaluate.holes": ("full", "ignore"),
    "evaluate.mask": ("auto", "gt", "pred"),
    "evaluate.protocol": ("native", "transcg", "cleargrasp"),
}


# Value ranges: (low, high, low inclusive). Numbers not listed must be finite and >= 0; every
# number in a list is checked like the key itself.
POSITIVE = (0.0, math.inf, False)
SHARE = (0.0, 1.0, True)
RANGES: dict[str, tuple[float, float, bool]] = {
    **{key: POSITIVE for key in (
        "io.depth_scale", "io.max_median_depth", "plane.threshold", "plane.iterations",
        "reconstruct.levels", "reconstruct.iterations", "reconstruct.sections",
        "reconstruct.onnx_resolution", "reconstruct.onnx_radius", "align.views", "align.rolls",
        "align.yaw_steps", "align.max_rests", "align.patches", "align.contact_points",
        "align.top_candidates", "align.depth_samples", "align.window", "grasp.max_width",
        "grasp.finger_length", "grasp.finger_thickness", "grasp.finger_height",
        "grasp.palm_width", "grasp.palm_height", "grasp.palm_depth", "grasp.base_to_tip",
        "grasp.depths", "grasp.friction", "grasp.seeds", "grasp.approaches",
        "grasp.pair_radius", "grasp.contact_band", "grasp.collision_points",
        "grasp.mesh_points", "grasp.stride", "grasp.nms_distance", "grasp.top_k",
        "synth.scenes", "synth.views", "synth.depth_scale", "synth.max_range",
        "synth.distance", "evaluate.plot_max_error")},
    **{key: SHARE for key in (
        "plane.min_share", "segment.max_object_share", "segment.min_score",
        "reconstruct.open_top_ratio",
        "reconstruct.open_explains", "reconstruct.foreground_ratio", "align.depth_quantile",
        "align.depth_min_share", "align.depth_agree", "synth.lying_fraction", "synth.hole_fraction",
        "synth.see_through_fraction")},
    "synth.elevation_deg": (0.0, 90.0, True),
    "align.depth_max_change": (0.0, 1.0, True),
    "align.depth_search": (0.0, 1.0, True),
}
MAX_INT = 2**31 - 1
ORDERED_PAIRS = ("synth.objects", "synth.distractors", "synth.distance", "synth.elevation_deg",
                 "synth.hole_fraction", "synth.see_through_fraction")


def _check_range(value: Any, key: str, origin: str, named: str | None = None) -> None:
    """Raise :class:`ConfigError` naming ``key`` (as ``named``, where the user wrote it so)
    where a number of ``value`` is out of range."""
    where = f"'{named or key}' in {origin}"
    numbers = value if isinstance(value, list) else [value]
    if key in ORDERED_PAIRS and (len(numbers) != 2 or numbers[0] > numbers[1]):
        raise ConfigError(f"{where}: expected [min, max] with min <= max, got {value!r}")
    low, high, inclusive = RANGES.get(key, (0.0, math.inf, True))
    for x in numbers:
        if isinstance(x, bool) or not isinstance(x, (int, float)):
            continue
        if not math.isfinite(x):
            raise ConfigError(f"{where}: expected a finite number, got {x!r}")
        if isinstance(x, int) and x > MAX_INT:
            raise ConfigError(f"{where}: must be <= {MAX_INT}, got {x!r}")
        if x < low or (x == low and not inclusive) or x > high:
            lo = f"{'>=' if inclusive else '>'} {low:g}"
            span = lo if high == math.inf else f"{lo} and <= {high:g}"
            raise ConfigError(f"{where}: must be {span}, got {x!r}")


def _coerce(value: Any, annotation: Any, key: str, origin: str) -> Any:
    """Check ``value`` against a field annotation; return it converted (int -> float only)."""
    where = f"'{key}' in {origin}"
    if annotation is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{where}: expected true/false, got {value!r}")
    if annotation is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ConfigError(f"{where}: expected an integer, got {value!r}")
    if annotation is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise ConfigError(f"{where}: expected a number, got {value!r}")
    if annotation is str:
        if isinstance(value, str):
            return value
        raise ConfigError(f"{where}: expected a string, got {value!r}")
    if typing.get_origin(annotation) is list:
        (item_type,) = typing.get_args(annotation)
        if isinstance(value, str) and item_type is str:  # "a,b" from --set or a flag
            value = [v.strip() for v in value.split(",") if v.strip()]
        if not isinstance(value, list):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        return [_coerce(v, item_type, key, origin) for v in value]
    raise ConfigError(f"{where}: unsupported type {annotation!r}")  # pragma: no cover


def _section_types(section_cls: type) -> dict[str, Any]:
    return typing.get_type_hints(section_cls)


def apply_mapping(cfg: Config, data: Mapping[str, Any], origin: str) -> Config:
    """Return a copy of ``cfg`` with ``data`` applied, checked: ``{section: {key: value}}``,
    the tuning constants also as ``{"advanced": {section: {key: value}}}``."""
    if data is None:
        return cfg
    if not isinstance(data, Mapping):
        raise ConfigError(f"{origin}: expected a mapping of sections, got {type(data).__name__}")
    cfg = dataclasses.replace(cfg)
    for section, values in data.items():
        if section == ADVANCED_SECTION:
            for inner, inner_values in _mapping(values, section, origin).items():
                if inner not in ADVANCED:
                    raise ConfigError(f"unknown section '{section}.{inner}' in {origin} (the "
                                      f"advanced sections: {', '.join(ADVANCED)})")
                _apply_section(cfg, inner, _mapping(inner_values, f"{section}.{inner}", origin),
                               origin, advanced=True)
            continue
        if section not in {f.name for f in dataclasses.fields(Config)}:
            raise ConfigError(f"unknown section '{section}' in {origin}")
        _apply_section(cfg, section, _mapping(values, section, origin), origin)
    return cfg


def _mapping(values: Any, name: str, origin: str) -> Mapping:
    """``values`` of section ``name``: a mapping ({} for an empty section)."""
    if values is None:
        return {}
    if not isinstance(values, Mapping):
        raise ConfigError(f"section '{name}' in {origin}: expected a mapping")
    return values


def _apply_section(cfg: Config, section: str, values: Mapping, origin: str,
                   advanced: bool = False) -> None:
    """Check ``values`` ({key: value}) of ``section`` and set them on ``cfg`` (in place);
    ``advanced``: they came from the advanced section, which holds tuning constants only."""
    current = getattr(cfg, section)
    hints = _section_types(type(current))
    updates = {}
    for key, value in values.items():
        full = f"{section}.{key}"
        named = f"{ADVANCED_SECTION}.{full}" if advanced else full  # as the user wrote it
        if key not in hints:
            raise ConfigError(f"unknown key '{named}' in {origin}")
        if advanced and not is_advanced(section, key):
            raise ConfigError(f"'{named}' in {origin}: {full} is a user-facing key, set under "
                              f"'{section}:' (not '{ADVANCED_SECTION}:')")
        value = _coerce(value, hints[key], named, origin)
        if full in CHOICES and value not in CHOICES[full]:
            raise ConfigError(
                f"'{named}' in {origin}: {value!r} is not one of {', '.join(CHOICES[full])}"
            )
        if full == "reconstruct.masks" and not value:
            raise ConfigError(f"'{named}' in {origin}: expected segment, gt or a folder")
        if full == "synth.resolutions":
            for item in value:
                w, x, h = item.partition("x")
                if not (x and w.isdigit() and h.isdigit() and int(w) > 0 and int(h) > 0):
                    raise ConfigError(f"'{named}' in {origin}: expected WIDTHxHEIGHT such "
                                      f"as 640x480, got {item!r}")
        _check_range(value, full, origin, named)
        updates[key] = value
    setattr(cfg, section, dataclasses.replace(current, **updates))


def parse_set(item: str) -> tuple[str, str, Any]:
    """Split ``section.key=value`` (``advanced.section.key=value``: section ``advanced``, name
    ``section.key``); the value is parsed as YAML (so 0.5, true, [1, 2] work)."""
    key, sep, raw = item.partition("=")
    section, dot, name = key.strip().partition(".")
    if not sep or not dot or not section or not name:
        raise ConfigError(f"--set {item!r}: expected section.key=value")
    if section == ADVANCED_SECTION and not all(name.partition(".")[::2]):
        raise ConfigError(f"--set {item!r}: expected {ADVANCED_SECTION}.section.key=value")
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError as exc:
        raise ConfigError(f"--set {item!r}: value is not valid YAML ({exc})") from None
    return section, name, value


def _nested(section: str, name: str, value: Any) -> dict:
    """The mapping :func:`apply_mapping` takes for one key named ``section.name``."""
    if section == ADVANCED_SECTION:
        inner, _, key = name.partition(".")
        return {section: {inner: {key: value}}}
    return {section: {name: value}}


def load_yaml(path: str | Path) -> dict:
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read config file ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: config file is not UTF-8 text") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: config file is not valid YAML ({exc})") from None
    return data or {}


def build_config(
    path: str | Path | None = None,
    sets: typing.Iterable[str] = (),
    flags: Mapping[str, Any] | None = None,
) -> Config:
    """Defaults, then the YAML file, then ``--set`` items, then explicit flags (None = not given).

    Parameters
    ----------
    path : path, optional
        YAML file of ``{section: {key: value}}`` (and ``advanced: {section: {key: value}}``).
    sets : iterable of str
        ``section.key=value`` (or ``advanced.section.key=value``) items, applied in order.
    flags : mapping of 'section.key' -> value, optional
        Values of command-line flags; ``None`` means the flag was not given.
    """
    cfg = Config()
    if path is not None:
        cfg = apply_mapping(cfg, load_yaml(path), str(path))
    for item in sets:
        cfg = apply_mapping(cfg, _nested(*parse_set(item)), "--set")
    for full, value in (flags or {}).items():
        if value is None:
            continue
        section, _, name = full.partition(".")
        cfg = apply_mapping(cfg, {section: {name: value}}, "the command line")
    if cfg.io.min_median_depth >= cfg.io.max_median_depth:
        raise ConfigError(f"'io.min_median_depth' ({cfg.io.min_median_depth:g}) must be below "
                          f"'io.max_median_depth' ({cfg.io.max_median_depth:g})")
    return cfg


def to_dict(cfg: Config) -> dict:
    """Every key by its section: ``{section: {key: value}}``, as the code reads them."""
    return dataclasses.asdict(cfg)


def to_layout(cfg: Config) -> dict:
    """The YAML layout of ``configs/default.yaml``: the user-facing keys by section (a section
    without any left out), then the tuning constants under ``advanced: {section: {key:
    value}}``."""
    flat = to_dict(cfg)
    layout: dict = {section: {k: v for k, v in values.items() if not is_advanced(section, k)}
                    for section, values in flat.items()
                    if any(not is_advanced(section, k) for k in values)}
    layout[ADVANCED_SECTION] = {section: {k: flat[section][k] for k in keys}
                                for section, keys in ADVANCED.items()}
    return layout
