"""What strata costs from Python, as ratios measured in one run (BENCHMARKS
"From Python"):

1. a built-in scene rendered from Python against the same render by the
   `strata` command (whole calls, alternated, medians);
2. an oracle written in Python: paths a second of MC, against the engine's
   own analytic target (a Rust oracle as cheap as a function can be).

    cargo build --release
    pip install ./python
    python python/examples/overhead.py target/release/strata
"""

import statistics
import subprocess
import sys
import tempfile
import time

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
