"""Procedural glassware as surfaces of revolution.

Meshes use sr3d's object frame (see :mod:`sr3d_cli.geometry.revolution`): origin at the centre
of the base, +z up the symmetry axis, height 1; the pose's ``scale`` is the height in metres.

A profile is a polyline of ``(r, z)`` points in metres that starts and ends on the axis
(``r == 0``); revolving it gives a closed, watertight surface. Open vessels (drinking glass,
beaker, goblet) run up the outer wall, over the rim and down the inner wall, so they have real
wall thickness and a visible inside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from sr3d_cli.geometry.revolution import open_vessel, revolve

KINDS = ("bottle", "glass", "flask", "goblet", "beaker", "vial")


@dataclass
class Glassware:
    kind: str
    profile: np.ndarray  # (n, 2) r, z in metres, ends on the axis
    height: float  # metres

    def unit_mesh(self, sections: int = 48) -> trimesh.Trimesh:
        """Watertight mesh in the object frame (height 1)."""
        return revolve(self.profile / self.height, sections)

    @property
    def max_radius(self) -> float:
        return float(self.profile[:, 0].max())


def _arc(r0, z0, r1, z1, n, bulge):
    """Points from (r0, z0) to (r1, z1) (excluding the start) bowed outwards by ``bulge`` metres."""
    t = np.linspace(0, 1, n + 1)[1:]
    r = r0 + (r1 - r0) * t + bulge * np.sin(np.pi * t)
    z = z0 + (z1 - z0) * t
    return list(zip(r, z))


def make_glassware(kind: str, rng: np.random.Generator) -> Glassware:
    """A random object of ``kind`` with plausible lab/kitchen proportions (metres)."""
    u = rng.uniform
    wall = u(0.0015, 0.003)
    if kind == "bottle":
        r, h = u(0.025, 0.045), u(0.16, 0.30)
        hb, rn = h * u(0.5, 0.65), r * u(0.3, 0.45)
        hs = h * u(0.12, 0.2)
        prof = [(0, 0), (r * 0.92, 0), (r, 0.006), (r, hb)]
        prof += _arc(r, hb, rn, hb + hs, 6, r * 0.15)
        prof += [(rn, h - 0.004), (rn * 0.9, h), (0, h)]
        return Glassware(kind, np.asarray(prof), h)
    if kind == "vial":
        r, h = u(0.008, 0.015), u(0.045, 0.09)
        prof = [(0, 0), (r * 0.85, 0), (r, 0.003), (r, h * 0.85), (r * 0.8, h * 0.88),
                (r * 0.8, h), (0, h)]
        return Glassware(kind, np.asarray(prof), h)
    if kind == "flask":  # Erlenmeyer
        rb, h = u(0.035, 0.06), u(0.10, 0.18)
        rn, hc = u(0.012, 0.02), h * u(0.6, 0.72)
        prof = [(0, 0), (rb * 0.95, 0), (rb, 0.004)]
        prof += _arc(rb, 0.004, rn, hc, 6, 0.0)
        prof += [(rn, h - 0.003), (rn * 1.15, h), (0, h)]
        return Glassware(kind, np.asarray(prof), h)
    if kind == "glass":  # tumbler, slightly tapered
        rb, h = u(0.025, 0.035), u(0.08, 0.14)
        rt = rb * u(1.0, 1.3)
        outer = [(0, 0), (rb * 0.95, 0), (rb, 0.004)] + _arc(rb, 0.004, rt, h, 4, 0.0)
        return Glassware(kind, open_vessel(outer, wall, u(0.006, 0.012)), h)
    if kind == "beaker":
        r, h = u(0.025, 0.05), u(0.06, 0.13)
        outer = [(0, 0), (r * 0.96, 0), (r, 0.003), (r, h - 0.003), (r * 1.06, h)]
        return Glassware(kind, open_vessel(outer, wall, u(0.003, 0.005)), h)
    if kind == "goblet":
        rf, hs, h = u(0.028, 0.04), u(0.05, 0.09), u(0.14, 0.22)
        rbowl, rrim = u(0.035, 0.048), None
        rrim = rbowl * u(0.75, 0.95)
        rs = u(0.004, 0.006)
        outer = [(0, 0), (rf, 0), (rf * 0.95, 0.004), (rs, 0.01), (rs, hs)]
        bowl_h = h - hs
        t = np.linspace(0, 1, 10)[1:]
        r_bowl = rs + (rbowl - rs) * np.sin(np.pi * 0.62 * t) / np.sin(np.pi * 0.62)
        r_bowl = np.minimum(r_bowl, rbowl)
        r_bowl[-3:] = np.linspace(r_bowl[-4], rrim, 4)[1:]
        outer += list(zip(r_bowl, hs + bowl_h * t))
        return Glassware(kind, open_vessel(outer, wall, hs + 0.008), h)
    raise ValueError(f"unknown glassware kind {kind!r}; choose from {', '.join(KINDS)}")
