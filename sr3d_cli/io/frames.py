"""Frame selection: ``--frames 000001,000007`` or ranges ``000001-000009`` / ``a..b``."""

from __future__ import annotations

from sr3d_cli.errors import ConfigError


def _key(frame_id: str):
    return (0, int(frame_id), frame_id) if frame_id.isdigit() else (1, 0, frame_id)


def sort_ids(ids) -> list[str]:
    """Numeric ids in numeric order, then the others alphabetically."""
    return sorted(set(ids), key=_key)


def select_frames(ids: list[str], spec: str | None) -> list[str]:
    """Frames of ``ids`` named by ``spec`` (None or empty: all), in ``ids`` order.

    Tokens are comma-separated: an id, ``first..last`` or, for numeric ids, ``first-last``
    (inclusive, numeric order). A token that names nothing is a usage error.
    """
    if not spec:
        return list(ids)
    chosen: set[str] = set()
    for token in (t.strip() for t in spec.split(",")):
        if not token:
            continue
        lo, sep, hi = token.partition("..")
        if not sep and token.count("-") == 1 and all(p.isdigit() for p in token.split("-")):
            lo, hi = token.split("-")
            sep = "-"
        if sep:
            lo_k, hi_k = _key(lo), _key(hi)
            if lo.isdigit() and hi.isdigit():
                lo_k, hi_k = (0, int(lo), ""), (0, int(hi), "\uffff")
            hits = [i for i in ids if lo_k <= _key(i) <= hi_k]
        else:
            hits = [i for i in ids if i == token or (token.isdigit() and i.isdigit()
                                                     and int(i) == int(token))]
        if not hits:
            raise ConfigError(f"--frames: {token!r} matches no frame")
        chosen.update(hits)
    return [i for i in ids if i in chosen]
