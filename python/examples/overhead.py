"""What strata costs from Python, as ratios measured in one run (BENCHMARKS
"From Python"):

1. a built-in scene rendered from Python against the same render by the
   `strata` command (whole calls, alternated, medians);
2. an oracle written in Python: paths a second of MC, against the engine's
   own analytic target (a Rust oracle as cheap as a function can be);
3. the engine's procedural target written with numpy (a vectorized oracle,
   many paths a call; the same image in expectation, its numbers drawn 17
   a path) against the same target in Rust, per method, and against the
   numpy function called one path at a time.

    cargo build --release
    pip install ./python
    python python/examples/overhead.py target/release/strata
"""

import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import strata

cli = sys.argv[1]
repeats = 5
args = dict(width=128, height=128, seed=1)
python, command = [], []
with tempfile.TemporaryDirectory() as out:
    for _ in range(repeats):
        start = time.perf_counter()
        strata.render("cornell", "pssmlt", spp=64, threads=2, **args)
        python.append(time.perf_counter() - start)
        start = time.perf_counter()
        subprocess.run(
            [cli, "render", "cornell", "--method", "pssmlt", "--spp", "64", "--width", "128",
             "--height", "128", "--seed", "1", "--threads", "2", "--out", f"{out}/cornell"],
            check=True, capture_output=True,
        )
        command.append(time.perf_counter() - start)
p, c = statistics.median(python), statistics.median(command)
print(f"Cornell box 128x128, PSSMLT, 64 spp: Python {p:.3f} s, the command {c:.3f} s: {p / c:.3f}x")


def gap(x, y, sampler):
    u, v = sampler.next_2d()
    return (x / 64 * v, 0.0, 0.0) if u < 0.1 else (0.0, 0.0, 0.0)


for threads in [1, 2]:
    py = strata.render(gap, "mc", spp=16, width=64, height=64, threads=threads)
    rust = strata.render("procedural", "mc", spp=256, width=64, height=64, threads=threads)
    a = py.stats["paths"] / py.stats["seconds"]
    b = rust.stats["paths"] / rust.stats["seconds"]
    print(f"{threads} thread(s): a Python oracle {a / 1e3:.0f} k paths/s ({1e6 / a:.2f} µs a path), "
          f"the engine's procedural target {b / 1e6:.1f} M paths/s: {b / a:.0f}x")


# The showcase of `ProceduralImage` (engine/src/analytic.rs): a dim rectangle,
# a ramp, three blobs and a small bright rectangle, times a random factor of
# mean 1 (up to 8 bounces of 3 v^2, each continued with probability 0.6,
# then 2 w). Here its 17 numbers are drawn up front.
BLOBS = [((0.3, 0.35), 0.08, (1.0, 0.3, 0.1)), ((0.7, 0.6), 0.12, (0.1, 0.5, 1.0)),
         ((0.5, 0.8), 0.03, (0.2, 1.0, 0.2))]


def inside(x, y, x0, y0, x1, y1):
    return ((x0 <= x) & (x < x1) & (y0 <= y) & (y < y1)).astype(np.float64)[:, None]


def procedural(width, height):
    @strata.vectorized(dimensions=17)
    def image(x, y, u):
        x, y = x / width, y / height
        g = inside(x, y, 0.0, 0.0, 0.5, 1.0) * (0.02, 0.02, 0.03) + x[:, None] * (0.1, 0.08, 0.05)
        for (cx, cy), s, c in BLOBS:
            g += np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))[:, None] * c
        g += inside(x, y, 0.8, 0.1, 0.85, 0.15) * (40.0, 36.0, 30.0)
        alive = np.cumprod(u[:, 0:16:2] < 0.6, axis=1)
        factor = np.prod(np.where(alive, 3 * u[:, 1:16:2] ** 2, 1.0), axis=1) * 2 * u[:, 16]
        return g * factor[:, None]

    return image


def per_second(r):
    return (r.stats["paths"] + r.stats["bootstrap_paths"]) / r.stats["seconds"]


size = dict(width=256, height=256, threads=1, seed=1)
numpy_image = procedural(256, 256)
for method in ["mc", "pssmlt", "stratified"]:
    rates = []
    for _ in range(3):
        a = per_second(strata.render(numpy_image, method, spp=16, **size))
        b = per_second(strata.render("procedural", method, spp=16, **size))
        rates.append((a, b))
    a, b = (statistics.median(r) for r in zip(*rates))
    print(f"procedural target, {method}, 256x256, 16 spp, 1 thread: numpy {a / 1e6:.2f} M paths/s "
          f"({1e6 / a:.2f} µs a path), Rust {b / 1e6:.2f} M paths/s: {b / a:.1f}x")


def one_path_a_call(x, y, sampler):
    u = np.array([[sampler.next_1d() for _ in range(17)]])
    rgb = numpy_image.function(np.array([x]), np.array([y]), u)[0]
    return (float(rgb[0]), float(rgb[1]), float(rgb[2]))


a = per_second(strata.render(numpy_image, "mc", spp=16, **size))
c = per_second(strata.render(one_path_a_call, "mc", spp=1, **size))
print(f"procedural target, MC: numpy {a / 1e6:.2f} M paths/s, the same function a path a call "
      f"{c / 1e3:.1f} k paths/s: {a / c:.0f}x")
