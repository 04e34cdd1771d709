"""MC, PSSMLT and stratified MCMC on the Cornell box: relMSE against a long
MC reference, against render time, plotted with matplotlib.

    pip install ./python matplotlib
    python python/examples/compare.py docs/figures/python/compare.png
"""

import sys

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import strata  # noqa: E402

SIZE = dict(width=96, height=96)
TIMES = [0.25, 0.5, 1.0, 2.0, 4.0]
SEEDS = 3

reference = strata.render("cornell", "mc", spp=4096, seed=1000, **SIZE).image
fig, ax = plt.subplots(figsize=(6, 4))
for method in ["mc", "pssmlt", "stratified"]:
    errors = []
    for t in TIMES:
        runs = [strata.render("cornell", method, time=t, seed=s, **SIZE) for s in range(SEEDS)]
        errors.append(sum(strata.compare(r.image, reference)["rel_mse"] for r in runs) / SEEDS)
        print(f"{method:10} {t:5.2f} s  relMSE {errors[-1]:.2e}")
    ax.loglog(TIMES, errors, marker="o", label=method)
ax.set_xticks(TIMES, [f"{t:g}" for t in TIMES])
ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
ax.set_xlabel("render time (s, 2 threads)")
ax.set_ylabel("relMSE against 4096-spp MC")
ax.set_title("Cornell box 96x96, mean of 3 seeds")
ax.grid(True, which="both", alpha=0.3)
ax.legend()
fig.tight_layout()
fig.savefig(sys.argv[1] if len(sys.argv) > 1 else "compare.png", dpi=120)
