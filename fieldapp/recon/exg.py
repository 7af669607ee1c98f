"""Excess green (ExG) on colour images, by colour key, and a station's threshold (Otsu's): how
plants are told from soil before any point exists.

Apart from :mod:`fieldapp.recon.filters` so that reading a session's stations needs numpy
alone, not SciPy: the early station reader (:mod:`fieldapp.recon.early`) runs in a process
forked before SciPy is imported.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import NDArray

OTSU_BINS = 256
SUM_LEVELS = 3 * 255 + 1
EXG_KEYS = 256 * SUM_LEVELS
"""Colour keys of excess green (:func:`exg_keys`): 2G - R - B over S = R + G + B is 3G / S - 1,
a function of the green level G and the sum S alone, so 196 608 keys hold every value."""
NO_KEY = EXG_KEYS
"""The key of a pixel left out (no depth): one past the last, never tallied, never green."""
NO_COLOUR_SUM = 48
"""A pixel whose R + G + B is at most this (16 levels a channel) has no colour: libfreenect2's
registration writes black (0, 0, 0) where the colour camera does not see the depth pixel, and a
JPEG of it (quality 90) leaves sums up to 32 with random hues; a level of noise moves a dark
pixel's chromaticity by 1 / (R + G + B), so ExG means nothing there (read as colour, the JPEG'd
black of a touching plot made Otsu's threshold leave no soil: 20 "plants", width RMSE 20 cm).
No lit soil or leaf of the simulator's plots is darker than 134."""
NOT_GREEN_EXG = 0.05
"""Excess green under which colour is not plant matter: leaves' is 0.2-0.5, the colour step's
thresholds 0.05-0.25. A point under it that the colour step kept is a leaf's rim or the soil
its rim rules grew into (``filters.not_green``); a group whose median is under it is no plant
(``plants._foreign``: an independent renderer's white sphere among leaves, its cap kept by the
weak green grown from the leaves touching it, 0.05)."""
VALLEY_SMOOTHING_BINS = 5
MIN_GREEN_CONTRAST = 0.1
"""Least difference of the mean ExG of Otsu's two classes for colour to separate plants: green
leaves on soil differ by 0.3-0.5, a grey or constant image by less than 0.05."""

MIXED_SHARE = 1.0 / 3.0
"""A pixel a third leaf, by its excess green between the soil's and the leaves' typical values,
is a plant's where the valley between them is filled with such mixes
(:func:`mixed_pixel_threshold`): the plant's thin parts kept, the soil a little green left to
the pass-through."""

MIN_SOIL_SHARE = 0.01
"""Least share of a station's measured pixels a set ExG threshold must leave as soil for the
soil sample (levelling, local ground, registration): seedling plots leave 99 %, a threshold
of -1 (every colour, as for white reference spheres among plants) leaves none."""

NOISE_SIGMAS = 4.0
"""A pixel is green only where its excess green stands this many times its brightness's noise
above the soil's (:func:`noise_floors`), whatever the station's threshold."""
NOISE_SUM_BIN = 24
"""Width (levels of R + G + B) of the brightness bins whose soil gives the noise."""
NOISE_MIN_PIXELS = 400
"""Least soil pixels a brightness bin needs to measure its noise; a bin with fewer takes its
nearest darker measured bin's, scaled by the sums (:func:`noise_floors`)."""

NO_COLOUR = "no colour"
NO_GREEN_CONTRAST = "colour has no green contrast"
NO_SOIL_LEFT = "the excess-green threshold leaves no soil"


@dataclass(frozen=True)
class Separation:
    """How a station's plants are told from the soil: ``"colour"`` (excess green) or
    ``"geometry"`` (height above the local ground, connectivity), and why geometry."""

    method: str
    reason: str = ""

    @property
    def by_geometry(self) -> bool:
        return self.method == "geometry"

    def describe(self) -> str:
        """One line for the report and the CLI."""
        if self.by_geometry:
            return f"plants separated by geometry: {self.reason}"
        return "plants separated by colour (excess green)"


BY_COLOUR = Separation("colour")


def green_contrast(
    exg: NDArray[np.float64],
    weights: NDArray[np.int64] | None = None,
    threshold: float | None = None,
) -> float:
    """The difference of the mean ExG (N,) of the classes either side of Otsu's threshold
    (``threshold`` when already known); 0 for a constant image. ``weights`` (N,): how many
    pixels have each value (see :func:`otsu_threshold`; default one each)."""
    if len(exg) == 0:
        return 0.0
    weights = np.ones(len(exg), dtype=np.int64) if weights is None else weights
    high = exg > (otsu_threshold(exg, weights) if threshold is None else threshold)
    count_high, count = int(weights[high].sum()), int(weights.sum())
    if count_high == 0 or count_high == count:
        return 0.0
    weighted = exg * weights
    return float(weighted[high].sum() / count_high - weighted[~high].sum() / (count - count_high))


def choose_separation(
    exg: NDArray[np.float64] | None,
    weights: NDArray[np.int64] | None = None,
    otsu: float | None = None,
) -> Separation:
    """Colour when every capture has a colour image (``exg`` (N,): the ExG of the measured
    pixels, or its distinct values and their ``weights``; ``otsu``: their Otsu threshold when
    already known) with green contrast, else geometry, saying why."""
    if exg is None:
        return Separation("geometry", NO_COLOUR)
    if green_contrast(exg, weights, otsu) < MIN_GREEN_CONTRAST:
        return Separation("geometry", NO_GREEN_CONTRAST)
    return BY_COLOUR


def keep_soil(
    separation: Separation,
    exg: NDArray[np.float64],
    threshold: float,
    weights: NDArray[np.int64] | None = None,
) -> Separation:
    """``separation``, or geometry when the colour ``threshold`` calls (nearly) every measured
    pixel (ExG (N,), or distinct values and their ``weights``) green: with no soil pixel the
    station has no ground to be levelled on and registration only the points above an
    unlevelled ground."""
    if separation.by_geometry or len(exg) == 0:
        return separation
    weights = np.ones(len(exg), dtype=np.int64) if weights is None else weights
    if int(weights[exg <= threshold].sum()) < MIN_SOIL_SHARE * int(weights.sum()):
        return Separation("geometry", NO_SOIL_LEFT)
    return separation


def excess_green(colors: NDArray[np.uint8]) -> NDArray[np.float64]:
    """ExG = 2g - r - b on chromaticity-normalised colour (r = R / (R + G + B)...), (N,) in
    [-1, 2]; black pixels get 0. The sums are exact in int16, so the one float64 division
    gives the same values as float64 arithmetic throughout, at a seventh of its cost."""
    r, g, b = (colors[:, channel].astype(np.int16) for channel in range(3))
    total = r + g + b
    total[total == 0] = 1
    return (2 * g - r - b) / total


def has_colour(colors: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """(N,) which of ``colors`` (N, 3) uint8 RGB carry colour: R + G + B above
    :data:`NO_COLOUR_SUM` (libfreenect2's holes and a JPEG's black do not)."""
    return colors.sum(axis=1, dtype=np.int32) > NO_COLOUR_SUM  # type: ignore[no-any-return]


def not_green_group(colors: NDArray[np.uint8]) -> bool:
    """Whether a group of points is not plant matter by its colour (``colors`` (N, 3)): the
    median excess green of those with colour (:func:`has_colour`) under
    :data:`NOT_GREEN_EXG`. A group with no colour at all is not judged by it (``False``):
    black says nothing of what a point is."""
    lit = colors[has_colour(colors)]
    return bool(len(lit)) and float(np.median(excess_green(lit))) < NOT_GREEN_EXG


GREY_SATURATION = 0.2
"""Saturation ((max - min) / max of R, G, B) under which a colour has no hue: grey, white or
near black. Soil, straw and a leaf's tip seen with the soil's colour (a colour pixel beside the
depth pixel) are brown or yellow, 0.3-0.5; an independent renderer's reference spheres and
their stands, and the shade on them, 0.05-0.13."""


def grey_group(colors: NDArray[np.uint8]) -> bool:
    """Whether a group of points has no hue (``colors`` (N, 3)): the median saturation of
    those with colour (:func:`has_colour`) under :data:`GREY_SATURATION`; a group with no
    colour at all is not judged by it (``False``)."""
    lit = colors[has_colour(colors)]
    if not len(lit):
        return False
    return float(np.median(saturation(lit))) < GREY_SATURATION


def hued(colors: NDArray[np.uint8]) -> NDArray[np.bool_]:
    """(N,) which of ``colors`` (N, 3) have colour (:func:`has_colour`) and a hue: saturation
    :data:`GREY_SATURATION` or more. A leaf has one, green or dry (tan, yellow, brown), and so
    has the soil; white and grey (the reference spheres, their stands, stakes, labels) and
    black do not."""
    return has_colour(colors) & (saturation(colors) >= GREY_SATURATION)


def saturation(colors: NDArray[np.uint8]) -> NDArray[np.float64]:
    """(N,) (max - min) / max of each colour's R, G, B (N, 3); 0 for black."""
    lit = colors.astype(np.float64)
    top = lit.max(axis=1)
    return (top - lit.min(axis=1)) / np.maximum(top, 1.0)  # type: ignore[no-any-return]


def exg_keys(colors: NDArray[np.uint8]) -> NDArray[np.int32]:
    """(N,) int32: the key ``G * 766 + S`` of each colour (N, 3) uint8 RGB, which fixes its
    excess green (:func:`exg_of_keys`). Cheaper than the ExG itself, and a station's pixels
    are then tallied (``np.bincount``) over :data:`EXG_KEYS` values instead of histogrammed
    as floats."""
    keys = np.multiply(colors[:, 1], SUM_LEVELS, dtype=np.int32)
    total = np.add(colors[:, 0], colors[:, 1], dtype=np.int32)
    total += colors[:, 2]
    keys += total
    return keys


@cache
def exg_of_keys() -> NDArray[np.float64]:
    """(EXG_KEYS,) float64: the excess green of each key of :func:`exg_keys`, bit for bit
    :func:`excess_green`'s value for the colours of that key (read-only)."""
    green, total = np.divmod(np.arange(EXG_KEYS, dtype=np.int64), SUM_LEVELS)
    difference = 3 * green - total  # 2G - R - B
    total[total == 0] = 1
    table = difference / total
    table.flags.writeable = False
    return table


@cache
def uncoloured_keys() -> NDArray[np.bool_]:
    """(EXG_KEYS + 1,) bool: which keys of :func:`exg_keys` (and :data:`NO_KEY`, not) are of
    pixels without colour (R + G + B at most :data:`NO_COLOUR_SUM`) (read-only)."""
    table = np.append(np.arange(EXG_KEYS) % SUM_LEVELS <= NO_COLOUR_SUM, False)
    table.flags.writeable = False
    return table


def exg_tally(keys: NDArray[np.int32]) -> NDArray[np.int64]:
    """(EXG_KEYS,) int64: how many of the pixels ``keys`` (N,) (see :func:`exg_keys`; those
    of :data:`NO_KEY` and those without colour, :func:`uncoloured_keys`, left out) have each
    key: a pixel with no colour is neither soil nor plant to the threshold."""
    tally = np.bincount(keys, minlength=NO_KEY + 1)[:EXG_KEYS]
    tally[_uncoloured_key_indices()] = 0
    return tally


@cache
def _uncoloured_key_indices() -> NDArray[np.intp]:
    return np.flatnonzero(uncoloured_keys()[:EXG_KEYS])


def exg_values(tally: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The distinct excess-green values (M,) of a :func:`exg_tally` and how many pixels have
    each (M,) int64, for :func:`otsu_threshold`, :func:`choose_separation` and
    :func:`keep_soil`. Two keys may share a value (the same ratio): it is then listed twice,
    which changes no histogram, count or mean."""
    present = np.flatnonzero(tally)
    return exg_of_keys()[present], tally[present]


def noise_floors(tally: NDArray[np.int64], threshold: float, sigmas: float) -> NDArray[np.float64]:
    """(SUM_LEVELS,) the least excess green a pixel of each brightness (R + G + B) needs to be
    told from the soil by colour, from a station's :func:`exg_tally`: the soil's median ExG in
    its brightness bin (:data:`NOISE_SUM_BIN` levels) plus ``sigmas`` times the soil's spread
    there (median minus 16th percentile: the lower side, which no leaf and no threshold
    truncates). Soil is the pixels at or below ``threshold``.

    A colour camera's noise is per channel, and ExG is a ratio: a level of noise moves a dark
    pixel's ExG by about 2.4 / (R + G + B), 0.07 at RGB 40 with 3 levels of noise, against
    thresholds of 0.15-0.25. Dark soil (in a plant's shadow, wet, a clod's shaded side) then
    passes the threshold pixel by pixel, and where it stands more than the pass-through above
    the local ground (clods) it became points and small "plants" (an independent renderer's
    plots: 1-3 soil "plants" of 200-1000 points, widths 6-9 cm too wide). Bright soil's spread
    is its texture, 0.01-0.04: its floor lies below every threshold measured, so nothing
    changes where the colour is clean. A bin with too few soil pixels to measure
    (:data:`NOISE_MIN_PIXELS`) takes the nearest darker measured bin's spread scaled by the
    ratio of their sums (noise over brightness), and its median; above the brightest measured
    bin the brightest's; a station with none measured gets no floor (minus infinity)."""
    exg = exg_of_keys()
    soil = (tally > 0) & (exg <= threshold)
    values, weights, which = exg[soil], tally[soil], _key_sums()[soil] // NOISE_SUM_BIN
    bins = (SUM_LEVELS + NOISE_SUM_BIN - 1) // NOISE_SUM_BIN
    measured = {}  # bin: (median, spread)
    for b in range(bins):
        in_bin = which == b
        if int(weights[in_bin].sum()) >= NOISE_MIN_PIXELS:
            median, low = _weighted_quantiles(values[in_bin], weights[in_bin], 0.5, 0.16)
            measured[b] = (median, median - low)
    floors = np.full(SUM_LEVELS, -np.inf)
    if not measured:
        return floors
    centre = (np.arange(bins) + 0.5) * NOISE_SUM_BIN
    source = min(measured)  # below the darkest measured bin, the darkest's
    for b in range(bins):
        if b in measured:
            source = b
        median, spread = measured[source]
        spread *= centre[source] / centre[b]  # 1 where measured
        floors[b * NOISE_SUM_BIN : (b + 1) * NOISE_SUM_BIN] = median + sigmas * spread
    return floors


@cache
def _key_sums() -> NDArray[np.int64]:
    """(EXG_KEYS,) the brightness R + G + B of each colour key (read-only)."""
    sums = np.arange(EXG_KEYS, dtype=np.int64) % SUM_LEVELS
    sums.flags.writeable = False
    return sums


def thresholds_by_key(threshold: float, floors: NDArray[np.float64]) -> NDArray[np.bool_]:
    """(EXG_KEYS + 1,) which colour keys are green: ExG above ``threshold`` and above the
    floor of their brightness (``floors`` (SUM_LEVELS,), :func:`noise_floors`); :data:`NO_KEY`
    never."""
    bound = np.maximum(threshold, floors[_key_sums()])
    return np.append(exg_of_keys() > bound, False)


def otsu_threshold(values: NDArray[np.float64], weights: NDArray[np.int64] | None = None) -> float:
    """Otsu's threshold of ``values`` (N,), placed in the valley between the two classes.
    With ``weights`` (N,) int64, positive, ``values[i]`` counts ``weights[i]`` times: the same
    threshold, bit for bit, as of the values repeated (a station's pixels, tallied by colour).

    Otsu's cut maximises the between-class variance; its two class means bracket the valley of
    the histogram. The threshold returned is the middle of the first lowest run of bins between
    the means: the same cut as Otsu's on a continuous histogram, and on a gappy one (soil, then
    a small class of yellow-green stems, then leaves) it does not split the small class off
    with the soil.
    """
    if len(values) == 0:
        raise ValueError("Otsu's threshold of no values")
    low, high = float(values.min()), float(values.max())
    if high - low < 1e-12:
        return high
    counts, edges = np.histogram(values, bins=OTSU_BINS, range=(low, high), weights=weights)
    centres = (edges[:-1] + edges[1:]) / 2.0
    weight_low = np.cumsum(counts)
    weight_high = weight_low[-1] - weight_low
    sum_low = np.cumsum(counts * centres)
    mean_low = sum_low / np.maximum(weight_low, 1)
    mean_high = (sum_low[-1] - sum_low) / np.maximum(weight_high, 1)
    between = weight_low * weight_high * (mean_low - mean_high) ** 2
    cut = int(np.argmax(between))
    return _valley(counts, edges, mean_low[cut], mean_high[cut])


SOIL_MODE_SPREADS = 3.0
"""Otsu's cut is taken to have fallen inside the soil when it lies between the station's median
ExG and this many spreads above it (:func:`above_the_soil`)."""


def above_the_soil(values: NDArray[np.float64], weights: NDArray[np.int64], valley: float) -> float:
    """``valley`` (Otsu's, :func:`otsu_threshold`), or, where it fell inside the soil, Otsu's
    threshold of the values above the soil's spread.

    Otsu's criterion favours the larger class: where the leaves are a sliver of a station's
    pixels (under 1 % at a plot's corner) and the soil's colour is noisy (its ExG spread 0.05),
    it cuts the soil's own hump in two: an independent renderer's corner stations with twice
    its colour noise got 0.015-0.017 against 0.20 elsewhere, 39 % of their pixels "green",
    and 61-75 soil "plants". The soil is the bulk of a field's pixels, so its median is the
    station's (``values`` (N,) counted ``weights`` (N,) times) and its spread the median minus
    the 16th percentile (the lower side, which no leaf reaches). A cut between that median
    and :data:`SOIL_MODE_SPREADS` spreads above it is inside the soil: the threshold is then
    Otsu's of what lies above those spreads (the soil's tail and the leaves). A cut above
    them, or below the median (leaves the bulk of the pixels: a canopy seen from above), is
    kept. The threshold moved is never under those spreads."""
    median, low = _weighted_quantiles(values, weights, 0.5, 0.16)
    bound = median + SOIL_MODE_SPREADS * (median - low)
    upper = values > bound
    if not median < valley < bound or not upper.any():
        return valley
    return max(bound, otsu_threshold(values[upper], weights[upper]))


def mixed_pixel_threshold(
    values: NDArray[np.float64], weights: NDArray[np.int64], valley: float
) -> float:
    """The threshold a station's pixels' excess green must pass to be a plant's: the lower of
    ``valley`` (Otsu's, :func:`otsu_threshold`) and :data:`MIXED_SHARE` of the way from the
    soil's typical value to the leaves' (the weighted medians of ``values`` (N,), each
    counted ``weights`` (N,) times, on either side of ``valley``).

    A pixel part leaf and part soil has an excess green between theirs. Where the colour
    keeps its chroma at half resolution (JPEG, the Kinect v2's own colour stream) every pixel
    of a leaf's rim, and the whole of a tip a pixel or two wide, is such a mix: the valley
    between the classes is a plateau, along which its lowest bin falls anywhere. On a rig 1.5
    m high at JPEG quality 75 it fell three quarters of the way to the leaves (a pixel had to
    be three quarters leaf) and the tips were lost: heights 1.63 cm RMSE, 0.40 with the same
    colour as PNG. Soil a little green is no plant by colour alone: beside a leaf it lies
    behind the leaf (the rim rules grow nothing from it), elsewhere on the local ground,
    where the pass-through drops it, at its own depth and its block's median alike
    (``filters.filter_station``); a leaf's pixel lost is lost. Where the classes are apart
    (a gap between them, no mixed pixels: PNG), the valley lies below this bound and stays.
    """
    soil = values <= valley
    if soil.all() or not soil.any():
        return valley
    soil_typical = _weighted_median(values[soil], weights[soil])
    leaf_typical = _weighted_median(values[~soil], weights[~soil])
    return min(valley, soil_typical + MIXED_SHARE * (leaf_typical - soil_typical))


def _weighted_median(values: NDArray[np.float64], weights: NDArray[np.int64]) -> float:
    return _weighted_quantiles(values, weights, 0.5)[0]


def _weighted_quantiles(
    values: NDArray[np.float64], weights: NDArray[np.int64], *shares: float
) -> list[float]:
    """The values at ``shares`` (0-1) of the weight of ``values`` (N,), each counted
    ``weights`` (N,) times."""
    order = np.argsort(values)
    cumulative = np.cumsum(weights[order])
    return [float(values[order][np.searchsorted(cumulative, cumulative[-1] * q)]) for q in shares]


def _valley(
    counts: NDArray[np.intp], edges: NDArray[np.float64], mean_low: float, mean_high: float
) -> float:
    """The middle of the first run of least-populated bins (after a light smoothing, so a
    stray empty bin in a tail is no valley) with centres in (mean_low, mean_high)."""
    centres = (edges[:-1] + edges[1:]) / 2.0
    inside = np.flatnonzero((centres > mean_low) & (centres < mean_high))
    if len(inside) == 0:
        return float((mean_low + mean_high) / 2.0)
    smooth = np.convolve(counts, np.ones(VALLEY_SMOOTHING_BINS), mode="same")
    lowest = inside[smooth[inside] == smooth[inside].min()]
    run_end = lowest[0]
    while run_end + 1 in lowest:
        run_end += 1
    return float((edges[lowest[0]] + edges[run_end + 1]) / 2.0)
