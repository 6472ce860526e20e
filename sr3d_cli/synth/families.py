"""Object families the generator draws: glassware of revolution and shapes that are not.

Families (``sr3d synth --families``):

- ``revolution``: bottle, glass, flask, goblet, beaker, vial (:mod:`sr3d_cli.synth.shapes`);
- ``handle``: mug, pitcher (with a spout): an open vessel with a swept handle joined into its
  wall;
- ``square``: square_bottle, rect_bottle: rounded-box cross-sections turning round at the neck;
- ``flat``: flat_bottle: an elliptic cross-section (a flask for the pocket, a shampoo bottle);
- ``open``: bowl, thin_glass: wide or thin-walled open vessels, in scenes seen from above.

Every mesh is watertight, in sr3d's object frame (:mod:`sr3d_cli.geometry.revolution`: origin
at the centre of the base, +z up, height 1; the pose's ``scale`` is the height in metres); a
handle lies towards +x, a spout towards -x. Sizes are those of kitchen and bathroom objects,
in metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh

from sr3d_cli.geometry.loft import Handle, loft, superellipse
from sr3d_cli.geometry.revolution import open_vessel, revolve
from sr3d_cli.synth.shapes import KINDS, make_glassware

FAMILIES: dict[str, tuple[str, ...]] = {
    "revolution": KINDS,
    "handle": ("mug", "pitcher"),
    "square": ("square_bottle", "rect_bottle"),
    "flat": ("flat_bottle",),
    "open": ("bowl", "thin_glass"),
}
DEFAULT_FAMILIES = ("revolution",)  # what `sr3d synth` draws unless told: the bundled samples
ALL = "all"  # every family
STANDING_ONLY = ("flask", "bowl", "thin_glass")  # never laid down (bowls and open glasses are
# drawn to be seen into from above; a flask's cone makes it roll)
SECTIONS = 48  # points per cross-section, as the revolution kinds' meshes
HANDLE_CELLS = (1, 2)  # a handle's wall patch: half-size in cells around and up the wall
HANDLE_SAMPLES = 29  # centre-line points of a handle
BASE_BEVEL = 0.004  # metres: height of the rounded edge of a base
LIP = 0.004  # metres: height of a bottle's lip, a little narrower than its neck
WALL_LEVELS = 18  # loops up a handled vessel's wall (besides those at the handle's joints):
# enough for its taper and belly to look smooth


@dataclass
class Shape:
    """One drawn object: ``mesh`` in the object frame (height 1), ``height`` metres, and for a
    surface of revolution its ``profile`` ``(n, 2)`` (r, z) in units of the height (how it lies
    on its side); None for the other families."""

    kind: str
    mesh: trimesh.Trimesh
    height: float
    profile: np.ndarray | None = None

    @property
    def can_lie(self) -> bool:
        return self.kind not in STANDING_ONLY


def kinds_for(names: Sequence[str]) -> tuple[str, ...]:
    """The kinds drawn from, each equally likely, for ``names``: families (:data:`FAMILIES`),
    single kinds, or ``all``. Kinds keep the registry's order whatever the order of ``names``,
    so a selection draws the same objects however it is written."""
    wanted: set[str] = set()
    for name in names:
        name = name.strip()
        if name == ALL:
            wanted.update(k for kinds in FAMILIES.values() for k in kinds)
        elif name in FAMILIES:
            wanted.update(FAMILIES[name])
        elif any(name in kinds for kinds in FAMILIES.values()):
            wanted.add(name)
        else:
            choices = ", ".join([ALL, *FAMILIES, *(k for ks in FAMILIES.values() for k in ks)])
            raise ValueError(f"unknown family or kind {name!r}; choose from {choices}")
    if not wanted:
        raise ValueError("no family or kind given")
    return tuple(k for kinds in FAMILIES.values() for k in kinds if k in wanted)


def make_shape(kind: str, rng: np.random.Generator) -> Shape:
    """A random object of ``kind`` (any family's)."""
    if kind in KINDS:
        glass = make_glassware(kind, rng)
        return Shape(kind, glass.unit_mesh(), glass.height, glass.profile / glass.height)
    builders = {"mug": _mug, "pitcher": _pitcher, "square_bottle": _square_bottle,
                "rect_bottle": _rect_bottle, "flat_bottle": _flat_bottle, "bowl": _bowl,
                "thin_glass": _thin_glass}
    if kind not in builders:
        raise ValueError(f"unknown object kind {kind!r}; choose from "
                         f"{', '.join(k for ks in FAMILIES.values() for k in ks)}")
    mesh, height = builders[kind](rng)
    mesh.apply_scale(1.0 / height)
    return Shape(kind, mesh, height)


# --- vessels with a handle -------------------------------------------------------------------

def _wall_levels(z0: float, z1: float, count: int, joints: list[float], step: float,
                 cells: int) -> np.ndarray:
    """Heights ``(k,)`` of the loops up a wall from z0 to z1: ``count`` even levels, except near
    each handle joint, where ``cells`` levels ``step`` apart lie on each side of the joint."""
    levels = np.linspace(z0, z1, count)
    for z in joints:
        levels = levels[np.abs(levels - z) > (cells + 0.5) * step]
    around = [z + d * step for z in joints for d in range(-cells, cells + 1)]
    return np.unique(np.concatenate([levels, around]))


def _handled_vessel(radius_at, h: float, *, wall: float, base: float,
                    joints: tuple[float, float], reach: float, half_size: tuple[float, float],
                    squareness: float, spout=None) -> trimesh.Trimesh:
    """An open vessel (outer radius ``radius_at(z)``, height ``h``, wall thickness ``wall``,
    inner floor at ``base``) with a D-shaped handle from height ``joints[0]`` down to
    ``joints[1]`` reaching ``reach`` out of the wall towards +x; its section's half-extents
    ``half_size`` (around the wall, in the handle's plane); ``squareness`` 2 rounds the D,
    larger squares it. ``spout(theta (n,) rad, z) -> (n,)``: optional factor on the radius.
    Metres."""
    du, dv = HANDLE_CELLS
    step = half_size[1] / dv  # loops near a joint: the patch is as tall as the tube
    levels = _wall_levels(BASE_BEVEL, h, WALL_LEVELS, list(joints), step, dv)
    r0 = radius_at(0.0)
    outer = [(0.0, 0.0), (0.95 * r0, 0.0)] + [(radius_at(z), z) for z in levels]
    profile = open_vessel(outer, wall, base)
    ring = profile[1:-1]
    theta = 2 * np.pi * np.arange(SECTIONS) / SECTIONS
    unit = np.column_stack([np.cos(theta), np.sin(theta)])
    loops = []
    for r, z in ring:
        factor = np.ones(SECTIONS) if spout is None else spout(theta, z)
        loops.append(np.column_stack([r * factor[:, None] * unit, np.full(SECTIONS, z)]))
    loops = np.asarray(loops)
    outer_rows = {round(z, 9): i for i, (r, z) in enumerate(ring[:len(outer) - 1])}
    ends = tuple((outer_rows[round(z, 9)], 0) for z in joints)
    angle = np.linspace(np.pi / 2, -np.pi / 2, HANDLE_SAMPLES)
    mid, half = (joints[0] + joints[1]) / 2, (joints[0] - joints[1]) / 2
    z = mid + half * np.sin(angle)
    z[0], z[-1] = joints  # exactly on the joint loops
    c = np.cos(angle)
    out = reach * np.sign(c) * np.abs(c) ** (2 / squareness)
    path = np.column_stack([np.array([radius_at(v) for v in z]) + out, np.zeros_like(z), z])
    path[[0, -1], 0] = loops[[ends[0][0], ends[1][0]], 0, 0]
    handle = Handle(ends, HANDLE_CELLS, path, half_size)
    return loft(loops, [0.0, 0.0, profile[0, 1]], [0.0, 0.0, profile[-1, 1]], [handle])


def _mug(rng: np.random.Generator) -> tuple[trimesh.Trimesh, float]:
    u = rng.uniform
    r, h = u(0.034, 0.045), u(0.075, 0.11)
    r_top = r * u(1.0, 1.12)

    def radius_at(z):
        return r + (r_top - r) * max(z - BASE_BEVEL, 0.0) / (h - BASE_BEVEL)

    joints = (h * u(0.72, 0.82), h * u(0.22, 0.34))
    mesh = _handled_vessel(radius_at, h, wall=u(0.003, 0.0045), base=u(0.006, 0.01),
                           joints=joints, reach=u(0.018, 0.028),
                           half_size=(u(0.004, 0.0055), u(0.005, 0.007)),
                           squareness=u(2.0, 3.0))
    return mesh, h


def _pitcher(rng: np.random.Generator) -> tuple[trimesh.Trimesh, float]:
    u = rng.uniform
    r, h = u(0.045, 0.06), u(0.13, 0.2)
    belly, top = r * u(1.0, 1.15), r * u(0.85, 1.0)

    def radius_at(z):
        return float(np.interp(z, [BASE_BEVEL, 0.45 * h, h], [r, belly, top]))

    lip = h * u(0.15, 0.25)  # height of the spout's rise below the rim
    pull, width = u(0.25, 0.45), u(0.35, 0.6)  # spout: radius gain at the rim, angular width

    def spout(theta, z):
        rise = np.clip((z - (h - lip)) / lip, 0.0, 1.0) ** 2
        off = np.angle(np.exp(1j * (theta - np.pi)))
        return 1.0 + pull * rise * np.exp(-(off / width) ** 2)

    joints = (h * u(0.7, 0.8), h * u(0.25, 0.38))
    mesh = _handled_vessel(radius_at, h, wall=u(0.0025, 0.004), base=u(0.006, 0.01),
                           joints=joints, reach=u(0.028, 0.042),
                           half_size=(u(0.0055, 0.0075), u(0.007, 0.009)),
                           squareness=u(2.0, 3.0), spout=spout)
    return mesh, h


# --- bottles with non-round cross-sections ---------------------------------------------------

def _sectioned_bottle(rng: np.random.Generator, a: float, b: float, p: float, h: float
                      ) -> trimesh.Trimesh:
    """A bottle whose body has the cross-section ``|x/a|^p + |y/b|^p = 1`` (metres), narrowing
    over a shoulder into a round neck, lipped at the top."""
    u = rng.uniform
    hb, hs = h * u(0.55, 0.68), h * u(0.12, 0.2)
    rn = min(u(0.009, 0.015), 0.8 * min(a, b))
    shoulder = 0.5 - 0.5 * np.cos(np.pi * np.linspace(0, 1, 8)[1:])  # eased blend, 0 -> 1
    rows = [(0.92, 0.0, a, b, p)]  # (scale, z, a, b, p)
    rows += [(1.0, z, a, b, p) for z in np.linspace(BASE_BEVEL, hb, 5)]
    rows += [(1.0, hb + hs * s, a + (rn - a) * s, b + (rn - b) * s, p + (2 - p) * s)
             for s in shoulder]
    rows += [(1.0, h - LIP, rn, rn, 2.0), (0.9, h, rn, rn, 2.0)]
    loops = np.asarray([np.column_stack([k * superellipse(SECTIONS, sa, sb, sp),
                                         np.full(SECTIONS, z)]) for k, z, sa, sb, sp in rows])
    return loft(loops, [0.0, 0.0, 0.0], [0.0, 0.0, h])


def _square_bottle(rng: np.random.Generator) -> tuple[trimesh.Trimesh, float]:
    u = rng.uniform
    a, h = u(0.025, 0.04), u(0.15, 0.25)
    return _sectioned_bottle(rng, a, a, u(4.0, 7.0), h), h


def _rect_bottle(rng: np.random.Generator) -> tuple[trimesh.Trimesh, float]:
    u = rng.uniform
    a, h = u(0.035, 0.055), u(0.14, 0.22)
    return _sectioned_bottle(rng, a, a * u(0.5, 0.8), u(4.0, 7.0), h), h


def _flat_bottle(rng: np.random.Generator) -> tuple[trimesh.Trimesh, float]:
    u = rng.uniform
    a, h = u(0.028, 0.045), u(0.12, 0.2)
    return _sectioned_bottle(rng, a, a * u(0.4, 0.65), 2.0, h), h


# --- open vessels seen from above ------------------------------------------------------------

def _bowl(rng: np.random.Generator) -> tuple[trimesh.Trimesh, float]:
    u = rng.uniform
    rim, h = u(0.055, 0.085), u(0.04, 0.07)
    foot = rim * u(0.35, 0.5)
    t = np.linspace(0, 1, 12)[1:]
    outer = [(0.0, 0.0), (foot, 0.0)]
    outer += list(zip(foot + (rim - foot) * np.sin(np.pi / 2 * t),
                      BASE_BEVEL + (h - BASE_BEVEL) * t))
    return revolve(open_vessel(outer, u(0.002, 0.0035), u(0.004, 0.007)), SECTIONS), h


def _thin_glass(rng: np.random.Generator) -> tuple[trimesh.Trimesh, float]:
    u = rng.uniform
    rb, h = u(0.028, 0.038), u(0.09, 0.15)
    rt = rb * u(1.05, 1.3)
    z = np.linspace(BASE_BEVEL, h, 6)
    outer = [(0.0, 0.0), (0.95 * rb, 0.0)] + list(zip(rb + (rt - rb) * (z - z[0]) / (h - z[0]), z))
    return revolve(open_vessel(outer, u(0.0007, 0.0012), u(0.006, 0.012)), SECTIONS), h
