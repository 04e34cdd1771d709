#!/usr/bin/env python3
"""Writes the glass sphere of caustic.pbrt and caustic.json: the same
triangles (48 x 24 facets, flat, no shading normals) as sphere.ply for
strata's pbrt reader and sphere.obj for Tungsten's mesh reader.

    python3 studies/tungsten/sphere.py
"""
import math
import pathlib

CENTER, RADIUS, SLICES, STACKS = (0.1, 0.5, 0.15), 0.5, 48, 24

vertices = [(CENTER[0], CENTER[1] + RADIUS, CENTER[2])]
for i in range(1, STACKS):
    theta = math.pi * i / STACKS
    for j in range(SLICES):
        phi = 2 * math.pi * j / SLICES
        vertices.append((
            CENTER[0] + RADIUS * math.sin(theta) * math.cos(phi),
            CENTER[1] + RADIUS * math.cos(theta),
            CENTER[2] + RADIUS * math.sin(theta) * math.sin(phi),
        ))
vertices.append((CENTER[0], CENTER[1] - RADIUS, CENTER[2]))
south = len(vertices) - 1


def ring(i, j):
    return 1 + (i - 1) * SLICES + j % SLICES


# Counter-clockwise seen from outside: normals point out.
faces = [(0, ring(1, j + 1), ring(1, j)) for j in range(SLICES)]
for i in range(1, STACKS - 1):
    for j in range(SLICES):
        a, b = ring(i, j), ring(i, j + 1)
        c, d = ring(i + 1, j), ring(i + 1, j + 1)
        faces += [(a, b, d), (a, d, c)]
faces += [(south, ring(STACKS - 1, j), ring(STACKS - 1, j + 1)) for j in range(SLICES)]

here = pathlib.Path(__file__).parent
coords = ["%.7f %.7f %.7f" % v for v in vertices]
(here / "sphere.obj").write_text(
    "# a glass sphere of 48 x 24 flat facets (sphere.py)\n"
    + "".join(f"v {c}\n" for c in coords)
    + "".join("f %d %d %d\n" % tuple(i + 1 for i in f) for f in faces)
)
(here / "sphere.ply").write_text(
    "ply\nformat ascii 1.0\ncomment a glass sphere of 48 x 24 flat facets (sphere.py)\n"
    f"element vertex {len(vertices)}\nproperty float x\nproperty float y\nproperty float z\n"
    f"element face {len(faces)}\nproperty list uchar int vertex_indices\nend_header\n"
    + "".join(f"{c}\n" for c in coords)
    + "".join("3 %d %d %d\n" % f for f in faces)
)
