"""What each stage output was made from, and whether it still matches.

Every stage output JSON carries a ``made_from`` record: the config keys that affect the stage
(``{"segment.min_area": 150, ...}``) and a fingerprint of each upstream file it read
(``{"masks": "sha256:1f2e...", ...}``). A stage whose recorded inputs differ
from the current ones is stale. An output without a record (written by other tools) cannot be
judged and counts as current.

Stages and what they depend on (DESIGN.md, "Scene folder"):

- every stage also records ``io.depth_scale``
- segment: rgb, depth, camera; ``segment.*``, ``plane.*``
- reconstruct: rgb, depth, camera, the instance masks; ``reconstruct.*`` (but ``masks``),
  ``plane.*``
- align: depth, camera, masks, the frame's meshes; ``align.*``, ``plane.*``
- repair: depth, camera, masks, poses, meshes; ``repair.*``, ``render.*``, ``plane.*``
- grasp: depth, camera, masks, repaired depth, poses, meshes; ``grasp.*``, ``plane.*``
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

from sr3d_cli.config import Config

STAGES = ("segment", "reconstruct", "align", "repair", "grasp")
SECTIONS = {
    "segment": ("segment", "plane"),
    "reconstruct": ("reconstruct", "plane"),
    "align": ("align", "plane"),
    "repair": ("repair", "render", "plane"),
    "grasp": ("grasp", "plane"),
}
NOT_RECORDED = {"reconstruct.masks"}  # recorded as the mask file it names, among the inputs
RECORD_KEY = "made_from"


def digest(data: bytes) -> str:
    """``sha256:HEX`` (16 hex digits) of a file's bytes: its fingerprint."""
    return f"sha256:{hashlib.sha256(data).hexdigest()[:16]}"


def fingerprint(path: Path | None) -> str:
    """:func:`digest` of a file; ``"none"`` where it is absent."""
    if path is None:
        return "none"
    try:
        return digest(Path(path).read_bytes())
    except OSError:
        return "none"


def config_keys(cfg: Config, stage: str) -> dict:
    """The config values that affect ``stage``, as ``{"section.key": value}``."""
    keys = {}
    for section in SECTIONS[stage]:
        for name, value in dataclasses.asdict(getattr(cfg, section)).items():
            if f"{section}.{name}" not in NOT_RECORDED:
                keys[f"{section}.{name}"] = value
    return keys


def made_from(cfg: Config, stage: str, inputs: dict[str, Path | None | list]) -> dict:
    """The record of a stage output: its config keys and its inputs' fingerprints. An input may
    be a list of paths (the meshes of a frame)."""
    prints = {}
    for name, value in sorted(inputs.items()):
        if isinstance(value, (list, tuple)):
            prints[name] = [fingerprint(p) for p in value]
        else:
            prints[name] = fingerprint(value)
    return {"config": config_keys(cfg, stage), "inputs": prints}


def record_of(document) -> dict | None:
    """The ``made_from`` record of a stage output JSON's ``document`` (None: none)."""
    record = document.get(RECORD_KEY) if isinstance(document, dict) else None
    return record if isinstance(record, dict) else None


def _short(value) -> str:
    text = json.dumps(value) if not isinstance(value, str) else value
    return text if len(text) <= 40 else text[:37] + "..."


def stale_reason(recorded: dict | None, current: dict, defaults: Config | None = None
                 ) -> str | None:
    """Why an output recorded as ``recorded`` does not match ``current`` (None: it matches, or
    it has no record). A key missing from an old record counts only where its value is not the
    built-in default."""
    if not recorded:
        return None
    defaults = defaults or Config()
    old_cfg, new_cfg = recorded.get("config", {}), current["config"]
    for key, value in new_cfg.items():
        if key in old_cfg:
            if old_cfg[key] != value:
                return f"{key} was {_short(old_cfg[key])}, now {_short(value)}"
        else:
            section, _, name = key.partition(".")
            if getattr(getattr(defaults, section), name, value) != value:
                return f"{key} is {_short(value)}, the output predates it"
    old_in, new_in = recorded.get("inputs", {}), current["inputs"]
    for name, value in new_in.items():
        if old_in.get(name) != value:
            return f"its {name} changed"
    return None
