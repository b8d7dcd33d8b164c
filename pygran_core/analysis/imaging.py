"""Image analysis of mixtures, as the original PyGran's ``analysis.imaging`` module.

The workflow: :func:`slice` renders each species of a configuration, slab by slab, as
black-and-white images (a stack of slices is a 3D image, one pixel thick per slice when
the slab thickness equals ``resol``); :func:`readImg` reads images back as arrays;
:func:`coarseDiscretize` bins a stack per species into cubic voxels of ``binsize`` pixels
and gives each species' volume fraction per voxel; from these,
:func:`intensitySegregation` is Danckwerts' intensity of segregation and
:func:`scaleSegregation` (Monte Carlo) and :func:`scaleSegregation_fft` (exact, by FFT)
his coefficient of correlation ``R(r)``. The same functions take images from X-ray
tomography or any other source.

Array convention: an image is indexed ``[i, j]`` with ``i`` along the image's width (its x)
and ``j`` along its height (its y), as PIL's pixel access; a stack adds the image number as
the last axis. ``flip=True`` reads ``[row, column]`` instead (images written by MATLAB).
Images are written and read with Pillow (``pip install pillow``, or the ``plot`` extra).
"""

from __future__ import annotations

import glob
import os
import re
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np

from pygran_core.analysis.particles import Particles
from pygran_core.errors import ConfigError, ReadError, UnsupportedFeature

__all__ = [
    "coarseDiscretize",
    "intensitySegregation",
    "readImg",
    "scaleSegregation",
    "scaleSegregation_fft",
    "slice",
]

ImageSet = str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | np.ndarray
_AXES = {"x": (0, 1, 2), "y": (1, 0, 2), "z": (2, 0, 1)}  # slicing axis, image width axis, height axis


def _pil() -> Any:
    try:
        from PIL import Image
    except ImportError:
        raise UnsupportedFeature(
            "analysis.imaging reads and writes images with Pillow: pip install pillow"
        ) from None
    return Image


def slice(
    Particles: Particles,
    zmin: float,
    zmax: float,
    axis: str,
    resol: float | tuple[int, int] | None = None,
    size: tuple[int, int] | float | None = None,
    output: str | os.PathLike[str] | None = None,
    imgShow: bool = False,
    *,
    origin: Sequence[float] | None = None,
) -> Any:
    """Render the slab ``zmin <= h <= zmax`` across ``axis`` ('x', 'y' or 'z') as an image.

    ``h`` (and the image's coordinates) are measured from ``origin``, by default the lower
    corner of the box enclosing every sphere of ``Particles``. Each sphere that cuts the
    slab's mid-plane is drawn as its cross-section there: the pixels whose centres lie within
    ``sqrt(r^2 - (h - h_mid)^2)`` of its centre are white (255), the rest black (0).
    ``resol`` is the length per pixel; ``size`` = (width, height) in pixels, by default
    enough for every sphere of ``Particles``. Slicing ``axis='x'`` gives images in the (y, z)
    plane, 'y' in (x, z) and 'z' in (x, y).

    Without ``resol`` the particles that cut the mid-plane are returned (as the original);
    with it the image as a uint8 array ``[i, j]``, also written to ``output`` if given and
    shown if ``imgShow``. Several species of one configuration give aligned images when they
    share ``origin`` and ``size``.

    ``resol`` and ``size`` may come in either order, as in the original's versions
    (``slice(P, zmin, zmax, 'z', size, resol, output)``): a pair is the size, a number the
    resolution.
    """
    if axis not in _AXES:
        raise ConfigError(f"slice: axis must be 'x', 'y' or 'z', not {axis!r}")
    resol, size = _resolution_and_size(resol, size)
    if not zmax >= zmin:
        raise ConfigError(f"slice: zmax ({zmax}) must not be below zmin ({zmin})")
    depth, wide, high = _AXES[axis]
    radii = np.asarray(Particles.radius, dtype=float)
    positions = Particles.positions
    lower = (positions - radii[:, None]).min(axis=0) if origin is None else np.asarray(origin, float)
    if lower.shape != (3,):
        raise ConfigError(f"slice: origin must be a point (x, y, z), got {origin!r}")
    relative = positions - lower
    mid = 0.5 * (zmin + zmax)
    cut = np.abs(relative[:, depth] - mid) < radii
    if resol is None:
        return Particles[cut]
    if not resol > 0:
        raise ConfigError(f"slice: resol (length per pixel) must be > 0, got {resol!r}")
    if size is None:
        upper = (relative + radii[:, None]).max(axis=0) if len(radii) else np.zeros(3)
        size = (int(np.ceil(upper[wide] / resol)), int(np.ceil(upper[high] / resol)))
    width, height = (int(n) for n in size)
    if width < 1 or height < 1:
        raise ConfigError(f"slice: size must be two positive pixel counts, got {size!r}")
    image = np.zeros((width, height), dtype=np.uint8)
    section = np.sqrt(radii[cut] ** 2 - (relative[cut, depth] - mid) ** 2)
    for (u, v), rc in zip(relative[cut][:, [wide, high]] / resol, section / resol):
        i0, i1 = max(int(np.floor(u - rc)), 0), min(int(np.ceil(u + rc)) + 1, width)
        j0, j1 = max(int(np.floor(v - rc)), 0), min(int(np.ceil(v + rc)) + 1, height)
        if i0 >= i1 or j0 >= j1:
            continue
        di = np.arange(i0, i1) + 0.5 - u
        dj = np.arange(j0, j1) + 0.5 - v
        disc = di[:, None] ** 2 + dj[None, :] ** 2 <= rc**2
        image[i0:i1, j0:j1][disc] = 255
    if output is not None or imgShow:
        picture = _pil().fromarray(np.ascontiguousarray(image.T), mode="L")
        if output is not None:
            picture.save(os.fspath(output))
        if imgShow:
            picture.show()
    return image


def _resolution_and_size(first: Any, second: Any) -> tuple[float | None, tuple[int, int] | None]:
    """``(resol, size)`` from :func:`slice`'s two arguments in either order: a pair of pixel
    counts is the size, a number the length per pixel."""

    def is_pair(value: Any) -> bool:
        return isinstance(value, (Sequence, np.ndarray)) and not isinstance(value, (str, bytes))

    if is_pair(first) and not is_pair(second):
        first, second = second, first
    if is_pair(first) or (second is not None and (not is_pair(second) or len(second) != 2)):
        raise ConfigError(
            f"slice: give one length per pixel (a number) and one size (width, height) in pixels, in "
            f"either order; got {first!r} and {second!r}"
        )
    return first, None if second is None else (int(second[0]), int(second[1]))


def _numbers(path: str) -> list[Any]:
    parts = re.split(r"(\d+)", path)
    return [int(p) if p.isdigit() else p for p in parts]


def _single(file: ImageSet) -> str | None:
    """The file ``file`` names when it is one file given by name (which reads as 2D), else None."""
    if isinstance(file, (str, os.PathLike)) and not glob.has_magic(os.fspath(file)):
        return os.fspath(file)
    return None


def _files(file: ImageSet, order: bool) -> list[str]:
    """The files of a stack: a glob pattern or a sequence of names."""
    if isinstance(file, (str, os.PathLike)):
        text = os.fspath(file)
        names = glob.glob(text)
        if not names:
            raise ReadError(f"No image file matches {text!r}")
    else:
        names = [os.fspath(f) for f in file]
        if not names:
            raise ConfigError("readImg: the list of image files is empty")
    return sorted(names, key=os.path.getmtime if order else _numbers)


def _read_one(path: str, flip: bool) -> np.ndarray:
    Image = _pil()
    try:
        with Image.open(path) as picture:
            data = np.asarray(picture)
    except FileNotFoundError:
        raise ReadError(f"Image file not found: {path}") from None
    except OSError as exc:
        raise ReadError(f"Cannot read image {path}: {exc}") from None
    return data if flip else np.swapaxes(data, 0, 1)


def readImg(
    file: ImageSet,
    order: bool = False,
    ncores: int | None = None,
    fillHoles: bool = False,
    flip: bool = False,
) -> np.ndarray:
    """Read image file(s) into an array.

    ``file`` is one image's name (gives a 2D array ``[i, j]``, or ``[i, j, channel]`` for
    colour), a glob such as ``'img*'`` or ``'slice*.png'``, or a list of names (a stack
    ``[i, j, k]`` or ``[i, j, channel, k]``, ``k`` the image number). A stack is in the
    numerical order of the names (``img10`` after ``img9``), or with ``order=True``
    chronological (file modification time). ``ncores`` threads read the files;
    ``fillHoles`` fills enclosed holes of the (binary) result with
    ``scipy.ndimage.binary_fill_holes`` and returns 0/1 integers; ``flip`` reads
    ``[row, column]`` (see the module docstring).
    """
    if ncores is not None and (isinstance(ncores, bool) or not isinstance(ncores, int) or ncores < 1):
        raise ConfigError(f"readImg: ncores must be a positive integer, got {ncores!r}")
    single = _single(file)
    if single is not None:
        data = _read_one(single, flip)
    else:
        names = _files(file, order)
        with ThreadPoolExecutor(max_workers=ncores or 1) as pool:
            images = list(pool.map(lambda name: _read_one(name, flip), names))
        shapes = {image.shape for image in images}
        if len(shapes) > 1:
            raise ConfigError(
                f"readImg: the images have different shapes {sorted(shapes)}; a stack needs one"
            )
        data = np.stack(images, axis=-1)
    if fillHoles:
        from scipy import ndimage

        return ndimage.binary_fill_holes(data).astype(int)
    return data


def _component(images: ImageSet, order: bool, fillHoles: bool, flip: bool) -> np.ndarray:
    data = (
        np.asarray(images)
        if isinstance(images, np.ndarray)
        else readImg(images, order, None, fillHoles, flip)
    )
    if data.ndim == 4:  # colour stack: the first channel
        data = data[:, :, 0, :]
    if data.ndim == 2:
        data = data[:, :, None]
    if data.ndim != 3:
        raise ConfigError(f"coarseDiscretize: an image stack has 2 to 4 dimensions, got shape {data.shape}")
    return data.astype(float)


def coarseDiscretize(
    images: ImageSet | Sequence[ImageSet],
    binsize: float,
    order: bool = False,
    fillHoles: bool = False,
    flip: bool = False,
) -> tuple[list[np.ndarray], list[float], list[float]]:
    """Volume fraction of each species in cubic voxels of ``binsize`` pixels.

    ``images`` holds one image set per species (each a glob, a list of files or an array,
    as :func:`readImg` reads them; a single set is one species). Pixel intensities are
    summed per voxel and species (voxel ``floor(index / binsize)`` along each axis), and
    each species' sum divided by the sum over species. Returns ``(volFrac, mean, var)``:
    one fraction array per species (0 in voxels without any material) and the mean and
    variance of each species' fraction over the voxels holding material.
    """
    if not binsize > 0:
        raise ConfigError(f"coarseDiscretize: binsize (pixels) must be > 0, got {binsize!r}")
    sets = [images] if isinstance(images, (str, os.PathLike, np.ndarray)) else list(images)
    if not sets:
        raise ConfigError("coarseDiscretize: no images given")
    data = [_component(item, order, fillHoles, flip) for item in sets]
    shapes = {d.shape for d in data}
    if len(shapes) > 1:
        raise ConfigError(f"coarseDiscretize: the species' image stacks differ in shape: {sorted(shapes)}")
    shape = data[0].shape
    index = [np.floor(np.arange(n) / binsize).astype(np.intp) for n in shape]
    coarse = tuple(int(i[-1]) + 1 for i in index)
    flat = np.ravel_multi_index(np.meshgrid(*index, indexing="ij"), coarse).ravel()
    grids = [
        np.bincount(flat, weights=d.ravel(), minlength=int(np.prod(coarse))).reshape(coarse) for d in data
    ]
    total = np.sum(grids, axis=0)
    filled = total > 0
    if not filled.any():
        raise ConfigError("coarseDiscretize: the images are black (no material in any voxel)")
    fractions = [np.where(filled, g / np.where(filled, total, 1.0), 0.0) for g in grids]
    return (
        fractions,
        [float(f[filled].mean()) for f in fractions],
        [float(f[filled].var()) for f in fractions],
    )


def intensitySegregation(
    images: Sequence[ImageSet], binsize: float, order: bool = False, flip: bool = False
) -> tuple[list[float], float, float]:
    """Danckwerts' intensity of segregation of a binary mixture from its images.

    ``images`` = (species A, species B) image sets. Returns ``(mean, var, I)``: the mean
    fractions of both species, the variance of A's fraction over the voxels with material
    and ``I = var / (mean_A mean_B)``: 1 when every voxel holds one species, 0 when every
    voxel holds both in the overall proportion.
    """
    _, mean, var = coarseDiscretize(images, binsize, order, False, flip)
    if len(mean) != 2:
        raise ConfigError(f"intensitySegregation needs the images of two species, got {len(mean)}")
    if mean[0] * mean[1] == 0:
        raise ConfigError("intensitySegregation: one species is absent from the images")
    return mean, var[0], var[0] / (mean[0] * mean[1])


def _correlation_inputs(
    images: ImageSet | Sequence[ImageSet], binsize: float, order: bool, fillHoles: bool, flip: bool
) -> tuple[np.ndarray, np.ndarray, float, float]:
    fractions, mean, var = coarseDiscretize(images, binsize, order, fillHoles, flip)
    filled = np.sum(fractions, axis=0) > 0
    if var[0] == 0:
        raise ConfigError("scaleSegregation: species A has the same fraction in every voxel (R is undefined)")
    return fractions[0], filled, mean[0], var[0]


def scaleSegregation(
    images: ImageSet | Sequence[ImageSet],
    binsize: float,
    samplesize: int,
    resol: float,
    maxDist: int | None = None,
    order: bool = False,
    fillHoles: bool = False,
    flip: bool = False,
    *,
    seed: int | np.random.Generator | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Danckwerts' coefficient of correlation ``R(r)`` of species A by Monte Carlo.

    For each distance ``d = 0, 1, ..., maxDist - 1`` voxels (default the voxel grid's
    diagonal), ``samplesize`` pairs of voxels with material are drawn: a uniform random
    voxel and the voxel nearest to the point ``d`` away in a uniformly random direction.
    ``R(d) = <(a_1 - m)(a_2 - m)> / var(a)``, ``a`` A's fraction (:func:`coarseDiscretize`).
    Distances that no pair reaches in 100 batches get ``nan``. Returns
    ``(r, R)`` with ``r = d * resol * binsize`` (``resol`` the length per pixel); ``seed``
    makes it reproducible.
    """
    if isinstance(samplesize, bool) or not isinstance(samplesize, (int, np.integer)) or samplesize < 1:
        raise ConfigError(f"scaleSegregation: samplesize must be a positive integer, got {samplesize!r}")
    a, filled, mean, var = _correlation_inputs(images, binsize, order, fillHoles, flip)
    shape = np.array(a.shape)
    if maxDist is None:
        maxDist = int(np.sqrt(3) * shape.max()) + 1
    if not maxDist >= 1:
        raise ConfigError(f"scaleSegregation: maxDist must be >= 1, got {maxDist!r}")
    rng = np.random.default_rng(seed)
    deviation = np.where(filled, a - mean, 0.0)
    R = np.full(int(maxDist), np.nan)
    batch = 4 * int(samplesize)
    for d in range(int(maxDist)):
        products: list[np.ndarray] = []
        found = 0
        for _ in range(100):
            start = np.column_stack([rng.integers(0, n, batch) for n in shape])
            cos_theta = 1.0 - 2.0 * rng.random(batch)
            phi = 2.0 * np.pi * rng.random(batch)
            sin_theta = np.sqrt(1.0 - cos_theta**2)
            step = np.column_stack((sin_theta * np.cos(phi), sin_theta * np.sin(phi), cos_theta))
            end = start + np.rint(d * step).astype(np.intp)
            inside = ((end >= 0) & (end < shape)).all(axis=1)
            start, end = start[inside], end[inside]
            both = filled[tuple(start.T)] & filled[tuple(end.T)]
            pairs = deviation[tuple(start[both].T)] * deviation[tuple(end[both].T)]
            products.append(pairs[: samplesize - found])
            found += products[-1].size
            if found >= samplesize:
                break
        if found:
            R[d] = np.concatenate(products).mean() / var
    return np.arange(int(maxDist)) * resol * binsize, R


def scaleSegregation_fft(
    images: ImageSet | Sequence[ImageSet],
    binsize: float,
    resol: float,
    order: bool = False,
    fillHoles: bool = False,
    flip: bool = False,
    Npts: int = 50,
) -> tuple[np.ndarray, np.ndarray]:
    """Danckwerts' ``R(r)`` of species A over every pair of voxels with material, by FFT.

    The sums ``sum (a_x - m)(a_y - m)`` and the pair counts over all ordered voxel pairs
    (self-pairs included) are correlations of the deviation and occupancy fields, computed
    exactly with zero-padded FFTs. Pairs are grouped into ``Npts`` bins of equal width in
    distance (0 to the grid's diagonal); each bin gives its mean distance and
    ``R = sum of products / (pairs * var)``. Empty bins are left out. Returns ``(r, R)``
    with ``r`` in lengths (voxels x ``binsize`` x ``resol``).
    """
    if isinstance(Npts, bool) or not isinstance(Npts, (int, np.integer)) or Npts < 1:
        raise ConfigError(f"scaleSegregation_fft: Npts must be a positive integer, got {Npts!r}")
    a, filled, mean, var = _correlation_inputs(images, binsize, order, fillHoles, flip)
    deviation = np.where(filled, a - mean, 0.0)
    padded = tuple(2 * n - 1 for n in a.shape)

    def autocorrelation(field: np.ndarray) -> np.ndarray:
        axes = (0, 1, 2)
        spectrum = np.fft.rfftn(field, padded, axes=axes)
        return np.fft.irfftn(spectrum * np.conj(spectrum), padded, axes=axes)

    products = autocorrelation(deviation)
    pairs = np.rint(autocorrelation(filled.astype(float)))
    lags = np.meshgrid(
        *[np.where(np.arange(m) < n, np.arange(m), np.arange(m) - m) for n, m in zip(a.shape, padded)],
        indexing="ij",
    )
    distance = np.sqrt(sum(lag.astype(float) ** 2 for lag in lags)).ravel()
    products, pairs = products.ravel(), pairs.ravel()
    edges = np.linspace(0.0, np.sqrt(sum((n - 1) ** 2 for n in a.shape)), int(Npts) + 1)
    which = np.minimum(np.searchsorted(edges, distance, side="right") - 1, int(Npts) - 1)
    count = np.bincount(which, weights=pairs, minlength=int(Npts))
    total = np.bincount(which, weights=products, minlength=int(Npts))
    where = np.bincount(which, weights=pairs * distance, minlength=int(Npts))
    seen = count > 0.5
    return where[seen] / count[seen] * resol * binsize, total[seen] / count[seen] / var
