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

import numpy as np

from . import _strata
from ._strata import (
    METHODS,
    Error,
    Render,
    Sampler,
    Vectorized,
    compare,
    ess,
    iat,
    invariance_error,
    reference,
    register_kernel,
    rhat,
)

__all__ = [
    "METHODS",
    "Error",
    "Render",
    "Sampler",
    "Vectorized",
    "check_purity",
    "compare",
    "ess",
    "iat",
    "invariance_error",
    "merge",
    "reference",
    "register_kernel",
    "render",
    "render_task",
    "rhat",
    "settings",
    "vectorized",
]

Oracle = Callable[[float, float, Sampler], "tuple[float, float, float]"]


def vectorized(dimensions: int) -> "Callable[[Callable[..., Any]], Vectorized]":
    """Decorator: an oracle written with numpy, whose paths each draw
    ``dimensions`` numbers, evaluated many paths a call::

        @strata.vectorized(dimensions=2)
        def disk(x, y, u):        # x, y: (N,) float64; u: (N, 2) float64
            inside = (u[:, 0] - 0.5) ** 2 + (u[:, 1] - 0.5) ** 2 < 0.25
            return np.stack([inside, inside, inside], axis=1)  # (N, 3)

        strata.render(disk, "pssmlt", width=64, height=64, spp=16)

    ``u`` holds each path's first ``dimensions`` numbers in ``[0, 1)``, the
    ones a per-path oracle ``f(x, y, sampler)`` draws with ``dimensions``
    calls of ``sampler.next_1d()``: the same arithmetic on them gives the
    same image bit for bit, at a fraction of the cost. The engine pauses its
    independent chains (rows, tiles) at their traces and hands their paths
    to ``function`` together, up to 1024 at once. ``function`` must be
    elementwise: row ``i`` of its result depends only on ``x[i]``, ``y[i]``
    and ``u[i]``. What it raises stops the render and is raised here.
    """
    return lambda function: Vectorized(function, dimensions)


def render(
    scene: Union[str, Oracle, Vectorized],
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
    preview: Optional[Callable[[np.ndarray], None]] = None,
    preview_every: float = 1.0,
    checkpoint: Optional[str] = None,
    checkpoint_every: Optional[float] = None,
    resume: Optional[str] = None,
    preset: Optional[str] = None,
    key: Union[bytes, str, None] = None,
    **settings: Any,
) -> Render:
    """Render ``scene`` with ``method`` and return a :class:`Render`.

    scene: a built-in (``"cornell"``, ``"door"``, ``"envplane"``,
        ``"caustic"``, ``"saturated"``, ``"pool"``), a pbrt-v3 file (a name
        that is neither raises ``FileNotFoundError``; what the loader skips
        is a ``UserWarning`` each), an analytic target (``"procedural"``, ``"mixture"``: their exact images
        are :func:`reference`), or an oracle written in Python: a callable
        ``f(x, y, sampler) -> (r, g, b)`` at film point ``(x, y)`` (pixels,
        ``y`` from the top) drawing every random number from
        ``sampler.next_1d()`` / ``sampler.next_2d()``; it must be a pure
        function of the point and the numbers (:func:`check_purity`), and
        needs ``width`` and ``height``. An exception it raises stops the
        render and is raised here with its traceback. Or a numpy oracle,
        many paths a call (:func:`vectorized`).
    method: one of :data:`METHODS` (``mc``, ``pssmlt``, ``replica``,
        ``stratified``, ``erpt``, ``multistage``).
    spp / time: the budget, paths per pixel or seconds (default 16 spp).
    seed: the same seed gives the same image, whatever ``threads``.
    threads: the engine's threads (default: every core; 1 for an oracle
        written in Python, whose paths wait for the GIL; a numpy oracle's
        paths are batched on the calling thread whatever ``threads``).
    path_sampler: ``unidirectional``, ``bidirectional``,
        ``bidirectional-no-splats`` or ``multiplexed`` (scenes only).
    progress: ``True`` for a progress bar (tqdm where installed), or a
        callable ``f(fraction, paths)`` called between rounds.
    preview: a callable given the image so far (a numpy array) at most
        every ``preview_every`` seconds.
    checkpoint: a file the render's state is written to every
        ``checkpoint_every`` seconds, when Ctrl-C stops it and when its
        budget is spent; ``resume`` continues from such a file (the same
        scene and settings; with the same budget the image is the
        uninterrupted render's, bit for bit; with a larger one it goes on).
    preset: ``"gruson2020"`` for stratified MCMC's paper settings.
    key: a secret (16 bytes or more) the checkpoints are sealed with
        (HMAC-SHA256) and ``resume`` opens them with: no one without it can
        forge or alter one (``strata render`` reads ``STRATA_CHECKPOINT_KEY``).
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
            preview=preview,
            preview_every=preview_every,
            checkpoint=checkpoint,
            checkpoint_every=checkpoint_every,
            resume=resume,
            preset=preset,
            key=_key(key),
            **settings,
        )
    finally:
        close()


def render_task(scene: Union[str, Oracle], method: str, index: int, count: int, **kwargs: Any) -> bytes:
    """Render task ``index`` of ``count`` of a split render (the arguments of
    :func:`render` but the callbacks and checkpoints); returns its part, to
    write to a file or give to :func:`merge`. Every method splits (stratified
    MCMC and multi-stage MLT by their ``runs``); ``key`` seals the part."""
    if "key" in kwargs:
        kwargs["key"] = _key(kwargs["key"])
    return _strata.render_task(scene, method, index, count, **kwargs)


def merge(parts: "list[Union[bytes, str]]", partial: bool = False,
          key: Union[bytes, str, None] = None) -> Render:
    """Merge the parts of a split render (bytes from :func:`render_task` or
    paths of part files, ``strata render --task-index`` writes them too)
    into its image: the unsplit render's, bit for bit. ``partial`` merges
    the parts given even if tasks are missing; ``key`` opens parts sealed
    with it (and refuses the others)."""
    return _strata.merge(list(parts), partial, _key(key))


def check_purity(oracle: Union[Oracle, Vectorized], width: int, height: int, trials: int = 16, seed: int = 0) -> None:
    """Check that ``oracle`` is a pure function of the film point and the
    numbers it draws (replayed ``trials`` times at the film's centre).
    Raises ``ValueError`` saying what differed."""
    _strata.check_purity_of(oracle, width, height, trials=trials, seed=seed)


def settings(method: str) -> "list[dict[str, Any]]":
    """Every setting of ``method``: name, kind, default, range or choices, help."""
    return _strata.settings(method)


def _key(key: Union[bytes, str, None]) -> Optional[bytes]:
    """A checkpoint key as bytes: at least 16 of them."""
    if key is None:
        return None
    key = key.encode() if isinstance(key, str) else bytes(key)
    if len(key) < 16:
        raise ValueError(f"key: at least 16 bytes, not {len(key)}")
    return key


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
