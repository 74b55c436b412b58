#!/usr/bin/env python3
"""Write a flat ring disc with chosen ring radii and spacings as OBJ.

`lodcloth mesh make disc` makes rings an even edge apart (6k points on ring
k). This makes a disc graded by hand, to ask where a mesh's resolution
matters: each ring is `radius:spacing` in millimetres, with
round(2π·radius / spacing) points (at least 6) starting at angle 0, and
neighbouring rings are stitched by the zipper of
`lodcloth_core::mesh::generate` (the next triangle takes the next point of
whichever ring is behind). The disc lies in the x–z plane at y = 0, centred
on the y axis, triangles facing +y, no texture coordinates, as the Cusick
specimen (config/meshes/cusick-specimen.obj). Used in the lab's notebook
(crates/lodcloth-lab/NOTEBOOK.md), "Bending for the drape, or for the fall":

    python3 examples/python/ring_disc.py band.obj \
        10:10,20:10,30:10,40:10,50:10,60:10,70:10,80:10,90:5,95:5,100:5,110:10,120:10,130:10,140:10,150:10

then a copy of config/scenes/cusick-drape.toml with `mesh` set to the file's
absolute path, stepped by `cargo run --release -p lodcloth-lab --example drape_scan -- run
COPY.toml --levels 100% --twins 4`.
"""

from __future__ import annotations

import argparse
import math


def zipper(lower: list[tuple[float, int]], upper: list[tuple[float, int]], out: list[tuple[int, int, int]]) -> None:
    i = j = 0
    while i + 1 < len(lower) or j + 1 < len(upper):
        if i + 1 >= len(lower):
            advance_lower = False
        elif j + 1 >= len(upper):
            advance_lower = True
        else:
            advance_lower = lower[i + 1][0] <= upper[j + 1][0]
        if advance_lower:
            out.append((lower[i][1], lower[i + 1][1], upper[j][1]))
            i += 1
        else:
            out.append((lower[i][1], upper[j + 1][1], upper[j][1]))
            j += 1


def ring_disc(rings: list[tuple[float, float]]) -> tuple[list[tuple[float, float, float]], list[tuple[int, int, int]]]:
    """Positions (m) and triangles of a disc with `rings` as (radius, spacing) in metres."""
    positions = [(0.0, 0.0, 0.0)]
    previous = [(0.0, 0), (1.0, 0)]
    triangles: list[tuple[int, int, int]] = []
    last_radius = 0.0
    for radius, spacing in rings:
        if not (radius > last_radius and spacing > 0.0):
            raise SystemExit(f"rings must grow outwards with a positive spacing: {radius * 1e3} mm after {last_radius * 1e3} mm")
        last_radius = radius
        m = max(6, round(2.0 * math.pi * radius / spacing))
        ring = []
        for i in range(m):
            t = i / m
            a = 2.0 * math.pi * t
            positions.append((radius * math.cos(a), 0.0, radius * math.sin(a)))
            ring.append((t, len(positions) - 1))
        ring.append((1.0, ring[0][1]))  # closed: the first point again at t = 1
        zipper(previous, ring, triangles)
        previous = ring
    faces = []
    for a, b, c in (t for t in triangles if len(set(t)) == 3):
        pa, pb, pc = positions[a], positions[b], positions[c]
        # Face +y: the y component of (b − a) × (c − a).
        if (pb[2] - pa[2]) * (pc[0] - pa[0]) - (pb[0] - pa[0]) * (pc[2] - pa[2]) < 0.0:
            b, c = c, b
        faces.append((a, b, c))
    return positions, faces


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="OBJ file to write")
    parser.add_argument("rings", help="radius:spacing in mm, comma-separated, growing outwards")
    args = parser.parse_args()
    try:
        rings = [tuple(float(x) / 1000.0 for x in r.split(":")) for r in args.rings.split(",")]
    except ValueError as e:
        raise SystemExit(f"rings: {e}")
    if any(len(r) != 2 for r in rings):
        raise SystemExit("rings: each is radius:spacing in mm")
    positions, faces = ring_disc(rings)  # type: ignore[arg-type]
    with open(args.out, "w") as f:
        f.write(f"# examples/python/ring_disc.py {args.rings}\n# {len(positions)} vertices, {len(faces)} triangles\n")
        for p in positions:
            f.write("v %r %r %r\n" % p)
        for a, b, c in faces:
            f.write(f"f {a + 1} {b + 1} {c + 1}\n")
    print(f"{args.out}: {len(positions)} vertices, {len(faces)} triangles")


if __name__ == "__main__":
    main()
