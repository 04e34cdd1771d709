"""strata from Python: every method renders the exact answer within noise,
bad input raises, Python oracles (a path a call, or numpy arrays of many)
render and stop cleanly, Ctrl-C stops a render, and a render is the
command's for the same seed, bit for bit."""

import math
import os
import re
import subprocess
import sys
import threading
import time
import _thread

import numpy as np
import pytest

import strata

# A hang detector, not a timing: a render that should stop in well under a
# second must stop within this.
HANG = 60.0


def test_every_method_renders_the_exact_image_mean_within_noise():
    """Sixteen seeds of each method at 64 paths a pixel (multi-stage MLT's
    smallest budget here) on the procedural image: the mean of their image
    means is within 4.5 standard errors (the seeds' spread, a t statistic of
    15 degrees of freedom: a false alarm in 2 500 per method) of the exact
    one."""
    exact = strata.reference("procedural", 48, 32).mean()
    for method in strata.METHODS:
        means = [
            strata.render("procedural", method, spp=64, seed=seed, width=48,
                          height=32).image.mean()
            for seed in range(16)
        ]
        mean = np.mean(means)
        error = np.std(means, ddof=1) / math.sqrt(len(means))
        z = (mean - exact) / error
        assert abs(z) < 4.5, f"{method}: mean {mean:.4f} against {exact:.4f} (z {z:+.1f})"


def test_an_image_is_a_float32_array_and_is_saved():
    r = strata.render("cornell", "mc", spp=2, width=24, height=16, seed=1)
    assert r.image.shape == (16, 24, 3) and r.image.dtype == np.float32
    assert np.isfinite(r.image).all() and r.image.mean() > 0
    assert r.stats["paths"] == 2 * 24 * 16 and r.stats["invalid_paths"] == 0
    assert r._repr_png_()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_stats_name_stratified_sweeps_and_multi_stage_grids():
    # Alg. 2 of Hoberock and Hart (2010) on a side of 24: doubling to 8,
    # then 10 linear steps to 24.
    r = strata.render("procedural", "multistage", spp=128, width=24, height=16, seed=1)
    assert r.stats["stages"] == [1, 2, 4, 8, 9, 11, 12, 14, 16, 17, 19, 20, 22, 24]
    s = strata.render("procedural", "stratified", spp=32, width=24, height=16, seed=1)
    assert s.stats["sweeps"] >= 1 and "stages" not in s.stats


def test_the_same_seed_gives_the_same_image_whatever_the_threads():
    one = strata.render("caustic", "pssmlt", spp=4, width=24, height=24, seed=5, threads=1)
    two = strata.render("caustic", "pssmlt", spp=4, width=24, height=24, seed=5, threads=2)
    assert np.array_equal(one.image, two.image)


@pytest.mark.skipif("STRATA_CLI" not in os.environ, reason="STRATA_CLI names the strata command (CI sets it)")
def test_a_render_is_the_commands_for_the_same_seed(tmp_path):
    """The same film from Python and from `strata render`: the EXRs they
    write are the same bytes."""
    for method in ["mc", "stratified"]:
        out = tmp_path / method
        subprocess.run(
            [os.environ["STRATA_CLI"], "render", "cornell", "--method", method, "--spp", "8",
             "--width", "32", "--height", "24", "--seed", "3", "--threads", "2", "--out", str(out)],
            check=True, capture_output=True,
        )
        r = strata.render("cornell", method, spp=8, width=32, height=24, seed=3, threads=2)
        r.save(str(tmp_path / f"{method}-python.exr"))
        assert (tmp_path / f"{method}-python.exr").read_bytes() == (tmp_path / f"{method}.exr").read_bytes()


def test_the_readme_s_python_line_runs():
    readme = open(os.path.join(os.path.dirname(__file__), "..", "..", "README.md")).read()
    lines = [line for line in readme.splitlines() if line.startswith('python -c "')]
    assert len(lines) == 1, lines
    code = lines[0][len('python -c "') : lines[0].rindex('"')]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=HANG)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "(256, 256, 3)", out.stdout


SCENE_64x32 = """
LookAt 0 0 5  0 0 0  0 1 0
Camera "perspective" "float fov" [ 40 ]
Film "image" "integer xresolution" [ 64 ] "integer yresolution" [ 32 ]
WorldBegin
  AttributeBegin
    AreaLightSource "diffuse" "rgb L" [ 4 4 4 ]
    Shape "trianglemesh" "integer indices" [ 0 1 2 ] "point P" [ -1 -1 0 1 -1 0 0 1 0 ]
  AttributeEnd
WorldEnd
"""


def test_a_scene_files_film_keeps_its_aspect_given_one_side(tmp_path):
    """A pbrt file's own film unless told; one side given keeps its aspect
    ratio (the other side was 256: a 64x32 film at width 16 was 16x256)."""
    scene = tmp_path / "scene.pbrt"
    scene.write_text(SCENE_64x32)
    shape = lambda **size: strata.render(str(scene), "mc", spp=1, **size).image.shape
    assert shape() == (32, 64, 3)
    assert shape(width=16) == (8, 16, 3)
    assert shape(height=4) == (4, 8, 3)
    assert shape(width=5, height=7) == (7, 5, 3)


def test_what_a_scene_file_holds_that_is_skipped_is_a_warning(tmp_path):
    """The loader's skipped directives reach Python as warnings, as they
    reach the command's user as notes."""
    scene = tmp_path / "scene.pbrt"
    scene.write_text(SCENE_64x32.replace("WorldEnd", 'Shape "sphere" "float radius" 1\nWorldEnd'))
    with pytest.warns(UserWarning, match='ignored Shape "sphere"'):
        strata.render(str(scene), "mc", spp=1, width=8)


def test_bad_settings_raise_value_and_type_errors():
    with pytest.raises(ValueError, match="unknown method"):
        strata.render("procedural", "metropolis")
    with pytest.raises(ValueError, match="chains"):
        strata.render("procedural", "pssmlt", chains=0)
    with pytest.raises(ValueError, match="`no_such_setting`: mc has no such setting"):
        strata.render("procedural", "mc", no_such_setting=1)
    with pytest.raises(ValueError):
        strata.render("procedural", "pssmlt", small_step="no-such-kernel")
    with pytest.raises(TypeError):
        strata.render("procedural", "pssmlt", chains=[1])
    with pytest.raises(ValueError):
        strata.render("procedural", "mc", spp=0)
    with pytest.raises(ValueError, match="spp: -1"):
        strata.render("procedural", "mc", spp=-1)
    # Python's ints outside an argument's range: a ValueError naming it.
    with pytest.raises(ValueError, match=r"seed: -1 is out of range \(0 to 2\*\*64 - 1\)"):
        strata.render("procedural", "mc", seed=-1)
    with pytest.raises(ValueError, match="seed: 18446744073709551616 is out of range"):
        strata.render("procedural", "mc", seed=2**64)
    with pytest.raises(ValueError, match="width: -1 is out of range"):
        strata.render("procedural", "mc", width=-1, height=4)
    with pytest.raises(ValueError, match="index: -1 is out of range"):
        strata.render_task("procedural", "mc", -1, 2)
    with pytest.raises(ValueError, match="seed: -3 is out of range"):
        strata.reference("mixture", seed=-3)
    with pytest.raises(ValueError, match="0x4 pixels has none"):
        strata.reference("procedural", width=0, height=4)
    with pytest.raises(ValueError, match="4x0 pixels has none"):
        strata.check_purity(lambda x, y, s: (0, 0, 0), 4, 0)
    with pytest.raises(ValueError, match="trials: -1 is out of range"):
        strata.check_purity(lambda x, y, s: (0, 0, 0), 4, 4, trials=-1)
    with pytest.raises(ValueError, match="dimensions: -2 is not in"):
        strata.vectorized(dimensions=-2)(lambda x, y, u: u)
    with pytest.raises(ValueError, match="threads: -2"):
        strata.render("procedural", "mc", threads=-2)
    with pytest.raises(ValueError):
        strata.render("procedural", "mc", time=float("nan"))
    with pytest.raises(ValueError):
        strata.render("procedural", "mc", spp=4, time=1.0)
    with pytest.raises(ValueError):
        strata.render("procedural", "mc", width=0, height=4)
    with pytest.raises(FileNotFoundError, match="no built-in scene of that name .cornell, door"):
        strata.render("cornel")
    with pytest.raises(TypeError):
        strata.render(42)
    with pytest.raises(ValueError, match="width and height"):
        strata.render(lambda x, y, s: (0, 0, 0))


def test_settings_are_the_engines():
    rows = {row["name"]: row for row in strata.settings("pssmlt")}
    assert rows["chains"]["default"] == 256 and rows["chains"]["range"] == (1, 65536)
    assert "kelemen" in rows["small_step"]["choices"]
    r = strata.render("procedural", "pssmlt", spp=4, width=16, height=16, chains=8, small_step="gaussian")
    assert r.stats["paths"] > 0


def light_through_a_gap(x, y, sampler):
    """An oracle written in Python: a tenth of the paths reach a light,
    brighter to the right. Its image mean is 0.25 in red."""
    u, v = sampler.next_2d()
    if u >= 0.1:
        return (0.0, 0.0, 0.0)
    b = x / 16 * 10 * v
    return (b, 0.8 * b, 0.6 * b)


def test_a_python_oracle_renders_its_exact_mean():
    """MC over 8 seeds: red's mean within 5 standard errors of 0.25."""
    means = [
        strata.render(light_through_a_gap, "mc", spp=16, width=16, height=8, seed=s).image[..., 0].mean()
        for s in range(8)
    ]
    z = (np.mean(means) - 0.25) / (np.std(means, ddof=1) / math.sqrt(8))
    assert abs(z) < 5, f"z {z:+.1f}"
    pssmlt = strata.render(light_through_a_gap, "pssmlt", spp=16, width=16, height=8, chains=16,
                           bootstrap_candidates=4096)
    assert np.isfinite(pssmlt.image).all() and pssmlt.stats["acceptance"] > 0


def test_an_exception_in_the_oracle_reaches_the_caller_and_stops_the_render():
    calls = []

    def broken(x, y, sampler):
        calls.append(1)
        if len(calls) > 50:
            raise ZeroDivisionError("the oracle's own error")
        return (1.0, 1.0, 1.0)

    start = time.monotonic()
    with pytest.raises(ZeroDivisionError, match="the oracle's own error") as raised:
        strata.render(broken, "mc", spp=10_000, width=64, height=64)
    assert time.monotonic() - start < HANG
    assert raised.traceback[-1].name == "broken"
    # It stopped: far fewer calls than the budget's 40 million paths.
    assert len(calls) < 1_000_000


def test_an_oracle_returning_other_than_three_numbers_is_told_what_it_returned():
    # Any sequence of three numbers is a colour.
    for returned in [(0.5, 0.25, 1.0), [0.5, 0.25, 1.0], np.array([0.5, 0.25, 1.0])]:
        r = strata.render(lambda x, y, s, r=returned: r, "mc", spp=1, width=2, height=2)
        assert np.array_equal(r.image, np.broadcast_to(np.float32([0.5, 0.25, 1.0]), (2, 2, 3)))
    for returned in [(1.0, 2.0), ("a", 0.0, 0.0), None]:
        with pytest.raises(TypeError, match=r"returns \(r, g, b\), three numbers, not " + re.escape(repr(returned))):
            strata.render(lambda x, y, s, r=returned: r, "mc", spp=1, width=2, height=2)


def test_a_sampler_kept_beyond_its_call_raises():
    kept = []

    def keeps(x, y, sampler):
        kept.append(sampler)
        return (sampler.next_1d(), 0.0, 0.0)

    strata.render(keeps, "mc", spp=1, width=2, height=2)
    with pytest.raises(RuntimeError, match="only during the call"):
        kept[0].next_1d()


def test_the_purity_check_finds_an_oracle_that_draws_outside_its_sampler():
    strata.check_purity(light_through_a_gap, 16, 8)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="not pure"):
        strata.check_purity(lambda x, y, s: (float(rng.random()), 0.0, 0.0), 16, 8)


def test_progress_is_reported_up_to_the_end():
    seen = []
    strata.render("procedural", "stratified", spp=32, width=32, height=32, progress=lambda f, n: seen.append((f, n)))
    assert seen and seen[-1][0] == 1.0
    assert all(a[0] <= b[0] and a[1] <= b[1] for a, b in zip(seen, seen[1:]))


def test_an_exception_in_the_progress_callback_stops_the_render():
    def fails(fraction, paths):
        raise RuntimeError("the callback's own error")

    with pytest.raises(RuntimeError, match="callback's own error"):
        strata.render("procedural", "mc", spp=64, width=32, height=32, progress=fails)


def test_ctrl_c_stops_a_long_render_with_keyboard_interrupt():
    """SIGINT half a second into a 20-second render: KeyboardInterrupt,
    well before the budget ends (a render deaf to it would return an image
    after 20 s instead)."""
    timer = threading.Timer(0.5, _thread.interrupt_main)
    timer.start()
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        strata.render("cornell", "pssmlt", time=20.0, width=32, height=32)
    assert time.monotonic() - start < 15


def test_diagnostics_on_known_series():
    rng = np.random.default_rng(1)
    iid = rng.standard_normal(4000)
    assert 0.8 * 4000 < strata.ess(list(iid)) < 1.2 * 4000
    # An AR(1) series with coefficient 0.9: IAT (1 + 0.9) / (1 - 0.9) = 19.
    ar = np.zeros(20000)
    for i in range(1, len(ar)):
        ar[i] = 0.9 * ar[i - 1] + rng.standard_normal()
    assert 14 < strata.iat(list(ar)) < 25
    same = [list(rng.standard_normal(1000)) for _ in range(4)]
    apart = [list(rng.standard_normal(1000) + k) for k in range(4)]
    assert strata.rhat(same) < 1.01 and strata.rhat(apart) > 1.5
    ref = strata.reference("procedural", 32, 24)
    assert strata.compare(ref, ref)["rel_mse"] == 0.0
    # MAPE is mean |I - R| / (R + 0.01) over luminance (Gruson et al. 2020).
    lum = ref @ np.array([0.2126, 0.7152, 0.0722])
    expected = np.mean(0.1 * lum / (lum + 0.01))
    assert strata.compare(ref * np.float32(1.1), ref)["mape"] == pytest.approx(expected, rel=1e-5)


def test_previews_are_numpy_images():
    seen = []
    strata.render("procedural", "pssmlt", spp=256, width=32, height=24, preview=seen.append, preview_every=1e-9)
    assert seen and all(p.shape == (24, 32, 3) and p.dtype == np.float32 for p in seen)


def test_a_render_stopped_by_ctrl_c_resumes_to_the_uninterrupted_image(tmp_path):
    """Ctrl-C with a checkpoint file: the state is saved, KeyboardInterrupt
    raised; resumed with the same budget, the image is the uninterrupted
    render's, bit for bit."""
    checkpoint = tmp_path / "cornell.ckpt"
    args = dict(spp=2048, width=32, height=32, seed=4, threads=2)
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    fractions = []
    with pytest.raises(KeyboardInterrupt):
        strata.render("cornell", "pssmlt", checkpoint=str(checkpoint),
                      progress=lambda f, n: fractions.append(f), **args)
    # Stopped inside its budget, and saved.
    assert fractions and fractions[-1] < 1.0
    assert checkpoint.is_file()
    resumed = strata.render("cornell", "pssmlt", resume=str(checkpoint), **args)
    whole = strata.render("cornell", "pssmlt", **args)
    assert resumed.stats["paths"] == whole.stats["paths"]
    assert np.array_equal(resumed.image, whole.image)


def test_tasks_merge_to_the_unsplit_render(tmp_path):
    args = dict(spp=8, width=32, height=24, seed=2)
    parts = [strata.render_task("cornell", "pssmlt", i, 3, **args) for i in range(3)]
    (tmp_path / "part-2.part").write_bytes(parts[2])
    merged = strata.merge([parts[1], parts[0], str(tmp_path / "part-2.part")])
    whole = strata.render("cornell", "pssmlt", **args)
    assert np.array_equal(merged.image, whole.image)
    with pytest.raises(strata.Error):
        strata.merge(parts[:2])
    assert strata.merge(parts[:2], partial=True).stats["paths"] < whole.stats["paths"]


def cauchy_offset(u, gamma=1 / 128):
    return gamma * math.tan(math.pi * (u - 0.5))


def cauchy_abs_cdf(x, gamma=1 / 128):
    return 2 / math.pi * math.atan(x / gamma)


def test_a_kernel_written_in_python_samples_the_target():
    """A Cauchy step registered from Python: PSSMLT with it renders the
    procedural image's exact mean within noise (16 seeds); a kernel that is
    not symmetric, or whose abs_cdf is no distribution function, is refused."""
    strata.register_kernel("py-cauchy", cauchy_offset, cauchy_abs_cdf)
    with pytest.raises(ValueError, match="registered already"):
        strata.register_kernel("py-cauchy", cauchy_offset, cauchy_abs_cdf)
    with pytest.raises(ValueError, match="not symmetric"):
        strata.register_kernel("lopsided", lambda u: u, cauchy_abs_cdf)
    with pytest.raises(ValueError, match="distribution function"):
        strata.register_kernel("no-law", cauchy_offset, lambda x: 2.0)
    exact = strata.reference("procedural", 24, 16).mean()
    means = [
        strata.render("procedural", "pssmlt", spp=16, width=24, height=16, seed=s, small_step="py-cauchy",
                      chains=64).image.mean()
        for s in range(16)
    ]
    z = (np.mean(means) - exact) / (np.std(means, ddof=1) / 4)
    assert abs(z) < 4.5, f"z {z:+.1f}"


def test_an_exception_in_a_python_kernel_stops_the_render():
    def fails_rarely(u):
        # Passes the registration's 256 points, fails in a render.
        if u > 0.9985:
            raise ZeroDivisionError("the kernel's own error")
        return cauchy_offset(u)

    strata.register_kernel("py-fails", fails_rarely, cauchy_abs_cdf)
    with pytest.raises(ZeroDivisionError, match="kernel's own error"):
        strata.render("procedural", "pssmlt", spp=64, width=24, height=16, small_step="py-fails", chains=64)
    # The error is the render's: the next one starts clean.
    strata.render("procedural", "pssmlt", spp=4, width=24, height=16, chains=64)


def gap_drawn_one_by_one(x, y, sampler):
    """light_through_a_gap with its two numbers drawn by next_1d: the numbers
    a vectorized oracle of two dimensions is handed."""
    u = sampler.next_1d()
    v = sampler.next_1d()
    if u >= 0.1:
        return (0.0, 0.0, 0.0)
    b = x / 16 * 10 * v
    return (b, 0.8 * b, 0.6 * b)


def gap_vectorized(batches):
    """The same arithmetic on arrays, noting each call's batch size."""

    @strata.vectorized(dimensions=2)
    def gap(x, y, u):
        batches.append(len(x))
        b = np.where(u[:, 0] < 0.1, x / 16 * 10 * u[:, 1], 0.0)
        return np.stack([b, 0.8 * b, 0.6 * b], axis=1)

    return gap


def test_a_numpy_oracle_renders_the_per_path_oracles_image_bit_for_bit():
    """Every method: the image and statistics of the oracle evaluated many
    paths a call are those of the same arithmetic a path a call, and its
    paths did come in batches."""
    budgets = {"erpt": dict(spp=16, chain_length=10), "multistage": dict(spp=256)}
    for method in strata.METHODS:
        args = dict(width=16, height=8, seed=3, **budgets.get(method, dict(spp=16)))
        one = strata.render(gap_drawn_one_by_one, method, **args)
        batches = []
        many = strata.render(gap_vectorized(batches), method, **args)
        assert np.array_equal(one.image, many.image), method
        del one.stats["seconds"], many.stats["seconds"]
        assert one.stats == many.stats, method
        assert max(batches) >= 8, f"{method}: batches of at most {max(batches)} paths"


NO_ROOM_FOR_COROUTINES = r"""
import resource, sys
import numpy as np
import strata
sys.path.insert(0, sys.argv[1])
from test_strata import gap_drawn_one_by_one, gap_vectorized

args = dict(width=64, height=64, seed=3, spp=16)
expected = strata.render(gap_drawn_one_by_one, "pssmlt", **args).image
strata.render(gap_vectorized([]), "pssmlt", **args)  # threads and pools made
with open("/proc/self/statm") as f:
    size = int(f.read().split()[0]) * resource.getpagesize()
# Room for a few dozen of the coroutines' 1 MB stacks, not for all.
resource.setrlimit(resource.RLIMIT_AS, (size + (48 << 20), resource.RLIM_INFINITY))
batches = []
image = strata.render(gap_vectorized(batches), "pssmlt", **args).image
print(np.array_equal(image, expected), min(batches), max(batches))
"""


@pytest.mark.skipif(not os.path.exists("/proc/self/statm"), reason="Linux only")
def test_a_numpy_oracle_without_room_for_its_coroutines_renders_the_same_image():
    """When no stack can be reserved for a task's coroutine, the task runs at
    once, its paths evaluated one by one: the same image, no crash."""
    here = os.path.dirname(os.path.abspath(__file__))
    out = subprocess.run(
        [sys.executable, "-c", NO_ROOM_FOR_COROUTINES, here],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr
    same, smallest, largest = out.stdout.split()
    assert same == "True"
    assert int(smallest) == 1 and int(largest) >= 8, out.stdout


def test_a_numpy_oracle_that_raises_or_returns_a_wrong_shape_stops_the_render():
    def broken(x, y, u):
        raise ZeroDivisionError("the numpy oracle's own error")

    with pytest.raises(ZeroDivisionError, match="numpy oracle's own error") as raised:
        strata.render(strata.Vectorized(broken, 3), "pssmlt", spp=10_000, width=64, height=64)
    assert raised.traceback[-1].name == "broken"
    with pytest.raises(ValueError, match=r"shape \((\d+), 3\) for \1 paths, not \[\1, 2\]"):
        strata.render(strata.Vectorized(lambda x, y, u: u, 2), "mc", spp=1, width=8, height=8)
    with pytest.raises(ValueError, match="dimensions"):
        strata.Vectorized(lambda x, y, u: u, 0)
    # Purity: checked on a batch of one path at a time.
    strata.check_purity(gap_vectorized([]), 16, 8)
    rng = np.random.default_rng(0)
    noisy = strata.Vectorized(lambda x, y, u: rng.random((len(x), 3)), 1)
    with pytest.raises(ValueError, match="not pure"):
        strata.check_purity(noisy, 16, 8)


def test_ctrl_c_stops_a_numpy_oracles_render():
    timer = threading.Timer(0.5, _thread.interrupt_main)
    timer.start()
    start = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        strata.render(gap_vectorized([]), "pssmlt", time=20.0, width=16, height=8)
    assert time.monotonic() - start < 15


def test_the_exact_invariance_check_of_kernels():
    """On a 1-D target cut into 48 cells (Šik 2018, sec. 3.3's parabola, a
    zero cell and a bump), every built-in kernel and one written in Python
    leave the target invariant up to rounding, with and without large
    steps; bad input raises."""
    cells = [(i / 48 - 0.5) ** 2 * (1 + 3 * math.exp(-200 * (i / 48 - 0.8) ** 2)) for i in range(48)]
    strata.register_kernel("py-cauchy-law", cauchy_offset, cauchy_abs_cdf)
    for kernel in ["kelemen", "gaussian", "adaptive", "py-cauchy-law"]:
        for p in [0.0, 0.3, 1.0]:
            assert strata.invariance_error(kernel, cells, p) < 1e-14, (kernel, p)
    with pytest.raises(ValueError, match="unknown kernel"):
        strata.invariance_error("nonesuch", cells)
    with pytest.raises(ValueError, match="importance"):
        strata.invariance_error("kelemen", cells[:-1] + [float("nan")])
    with pytest.raises(ValueError, match="large_step_probability"):
        strata.invariance_error("kelemen", cells, 1.5)
    with pytest.raises(ValueError, match="cells"):
        strata.invariance_error("kelemen", [1.0])


def test_sealed_checkpoints_and_parts_open_with_their_key_only(tmp_path):
    """With a key, checkpoints and parts are sealed (HMAC-SHA256): resume and
    merge open them with it, refuse them without it or with another."""
    key = b"the cluster's secret, 32 bytes.."
    ckpt = tmp_path / "r.ckpt"
    args = dict(spp=8, width=24, height=16, seed=3)
    whole = strata.render("procedural", "pssmlt", checkpoint=str(ckpt), key=key, **args)
    assert ckpt.read_bytes().endswith(b"STRATAsl")
    again = strata.render("procedural", "pssmlt", resume=str(ckpt), key=key, **args)
    assert np.array_equal(again.image, whole.image)
    with pytest.raises(strata.Error, match="sealed"):
        strata.render("procedural", "pssmlt", resume=str(ckpt), **args)
    with pytest.raises(strata.Error, match="another key"):
        strata.render("procedural", "pssmlt", resume=str(ckpt), key=b"x" * 32, **args)
    with pytest.raises(ValueError, match="16 bytes"):
        strata.render("procedural", "pssmlt", key="short", **args)
    parts = [strata.render_task("procedural", "pssmlt", i, 2, key=key, **args) for i in range(2)]
    assert np.array_equal(strata.merge(parts, key=key).image, whole.image)
    with pytest.raises(strata.Error, match="sealed"):
        strata.merge(parts)
