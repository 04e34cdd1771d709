"""strata: an embeddable Markov-chain Monte Carlo engine for light transport.

Render a built-in scene, a pbrt-v3 file, an analytic target with a known
image, or an oracle written in Python, with any of the engine's methods,
and get the image as a numpy array::

    import strata
    r = strata.render("cornell", "stratified", spp=64, width=320, height=320)
    r.image          # 320 x 320 x 3 float32, linear
    r.stats          # paths, invalid paths, acceptance, seconds, ...
    r.save("cornell.exr")

Settings are the engine's (``strata.settings("pssmlt")`` lists them with
their defaults and ranges, the names of ``strata settings`` and the C API),
given as keyword arguments: ``strata.render("caustic", "replica",
exchange="is-permutation", replicas=8)``. A bad setting raises
``ValueError``; a failed render ``strata.Error``. The GIL is released while
rendering; Ctrl-C stops the render between rounds (``KeyboardInterrupt``).
"""

from __future__ import annotations

import sys
from typing import Any, Callable, Optional, Union

from . import _strata
from ._strata import METHODS, Error, Render, Sampler, compare, ess, iat, reference, rhat

__all__ = [
    "METHODS",
    "Error",
    "Render",
    "Sampler",
    "check_purity",
    "compare",
    "ess",
    "iat",
    "reference",
    "render",
    "rhat",
    "settings",
]

Oracle = Callable[[float, float, Sampler], "tuple[float, float, float]"]


def render(
    scene: Union[str, Oracle],
    method: str = "pssmlt",
    *,
    spp: Optional[int] = None,
    time: Optional[float] = None,
    seed: int = 0,
    threads: Optional[int] = None,
    path_sampler: str = "unidirectional",
    width: Optional[int] = None,
    height: Optional[int] = None,
    progress: Union[bool, Callable[[float, int], None], None] = None,
    preset: Optional[str] = None,
    **settings: Any,
) -> Render:
    """Render ``scene`` with ``method`` and return a :class:`Render`.

    scene: a built-in (``"cornell"``, ``"door"``, ``"envplane"``,
        ``"caustic"``, ``"saturated"``, ``"pool"``), a pbrt-v3 file, an
        analytic target (``"procedural"``, ``"mixture"``: their exact images
        are :func:`reference`), or an oracle written in Python: a callable
        ``f(x, y, sampler) -> (r, g, b)`` at film point ``(x, y)`` (pixels,
        ``y`` from the top) drawing every random number from
        ``sampler.next_1d()`` / ``sampler.next_2d()``; it must be a pure
        function of the point and the numbers (:func:`check_purity`), and
        needs ``width`` and ``height``. An exception it raises stops the
        render and is raised here with its traceback.
    method: one of :data:`METHODS` (``mc``, ``pssmlt``, ``replica``,
        ``stratified``, ``erpt``, ``multistage``).
    spp / time: the budget, paths per pixel or seconds (default 16 spp).
    seed: the same seed gives the same image, whatever ``threads``.
    threads: the engine's threads (default: every core; 1 for an oracle
        written in Python, whose paths wait for the GIL).
    path_sampler: ``unidirectional``, ``bidirectional``,
        ``bidirectional-no-splats`` or ``multiplexed`` (scenes only).
    progress: ``True`` for a progress bar (tqdm where installed), or a
        callable ``f(fraction, paths)`` called between rounds.
    preset: ``"gruson2020"`` for stratified MCMC's paper settings.
    settings: any of the method's settings by name (:func:`settings`).
    """
    callback, close = _progress(progress)
    try:
        return _strata.render(
            scene,
            method,
            spp=spp,
            time=time,
            seed=seed,
            threads=threads,
            path_sampler=path_sampler,
            width=width,
            height=height,
            progress=callback,
            preset=preset,
            **settings,
        )
    finally:
        close()


def check_purity(oracle: Oracle, width: int, height: int, trials: int = 16, seed: int = 0) -> None:
    """Check that ``oracle`` is a pure function of the film point and the
    numbers it draws (replayed ``trials`` times at the film's centre).
    Raises ``ValueError`` saying what differed."""
    _strata.check_purity_of(oracle, width, height, trials=trials, seed=seed)


def settings(method: str) -> "list[dict[str, Any]]":
    """Every setting of ``method``: name, kind, default, range or choices, help."""
    return _strata.settings(method)


def _progress(progress):
    """The progress callback for ``progress``, and what closes it."""
    if progress is None or progress is False:
        return None, lambda: None
    if callable(progress):
        return progress, lambda: None
    try:
        from tqdm import tqdm  # type: ignore[import-not-found]

        bar = tqdm(total=1000, unit="‰", leave=False)

        def tick(fraction: float, paths: int) -> None:
            bar.n = int(fraction * 1000)
            bar.set_postfix(paths=paths, refresh=False)
            bar.refresh()

        return tick, bar.close
    except ImportError:

        def line(fraction: float, paths: int) -> None:
            sys.stderr.write(f"\r{100 * fraction:5.1f} %  {paths} paths")
            sys.stderr.flush()

        return line, lambda: sys.stderr.write("\n")
