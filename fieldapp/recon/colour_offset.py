"""How far a station's colour images are registered off their depth, and the colour moved back.

A Kinect v2's colour image is registered to its depth through a calibration (libfreenect2's,
the SDK's, a user's own) that can leave it a few pixels off throughout. A pixel or two at a
surface's rim the colour filters already allow for (``scans.grown_over_edges``), but a whole
image off by two pixels gives an upright leaf's tip, one or two pixels wide seen from above,
the soil's colour beside it: read as soil, the tops of the plants were lost (heights 1.1 cm
RMSE instead of 0.4 on a rig 1.5 m high, each plant up to 3.9 cm low).

The offset is found where colour and depth must agree: across a depth edge (two neighbouring
pixels on surfaces more than a few per cent of their distance apart, a leaf's rim over the
soil) the colour changes too. Each candidate offset (dx, dy), up to :data:`MAX_OFFSET_PX` a
side, is scored by the mean excess-green difference across the station's depth edges read
that far off; the colour lies where that contrast peaks. Pooled over a station's views it
peaks sharply (0.15-0.17 against 0.05-0.08 a pixel off on simulated plots), and it needs no
plant model, no threshold and no colour class: any object standing in front of another of a
different colour aligns it. The offset is integral: the colour is moved, not resampled (a
blend of a leaf's and the soil's colour is neither), and what remains is within the pixel the
rim filters allow for. The same registration error's parallax (an error in the colour
camera's baseline shifts the colour by an amount that falls with distance) is not modelled:
over a plot's 1-3 m it is within a pixel of one offset.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import NDArray

from fieldapp.recon.exg import NO_KEY, exg_of_keys, uncoloured_keys

MAX_OFFSET_PX = 4
"""The largest offset a side (pixels) looked for: a registration a pixel or two off, and
twice that; beyond it the registration is wrong rather than off (the search's border is said)."""
PAIRS_PER_FRAME = 1500
"""Depth-edge pairs of a frame scored (evenly spaced over its edges): 1500 per frame, 12 000
a station, set the offset's peak apart from its neighbours hundreds of times over their
spread, at a few milliseconds a frame."""
MIN_PAIRS = 1000
"""Fewer depth-edge pairs with colour on both sides than this over a station (bare soil, a
flat plot) tell no offset: the colour is left where it was registered."""
MIN_PEAK_RATIO = 1.15
"""The colour is moved only where the contrast at the offset found is at least this many times
the contrast where it was registered: a clear peak. Colour two pixels off gives 3-5 times as
PNG, 1.3-1.5 times as JPEG (quality 75: its chroma at half resolution blurs the peak over two
pixels); where nothing tells (bare soil) the best offset's contrast is 1.01-1.04 times the
registered one's, and a JPEG's registered where it belongs up to 1.02 times (its peak that
wide). A half-pixel offset, which moving by a whole pixel would not mend, stays put.
"""

MIN_PEAK_RATIO_WITH_HOLES = 2.0
"""The same where more than :data:`HOLES_SHARE` of the measured pixels have no colour
(libfreenect2's black beside every near edge, ``--color-holes``): the bands lie on one side of
the edges, so the pairs read at each offset are not the same ones, and stored as JPEG the
black dulls the colour beside it on that side only. A plot registered in place then peaked a
pixel sideways at 1.22-1.41 times the registered contrast (JPEG quality 80, in the sun: moved,
width RMSE 2.28 -> 3.18 cm); colour really off by two or three pixels with holes peaks at 3-7
times (PNG)."""
HOLES_SHARE = 0.01

_OFFSETS = np.array(
    [
        (dx, dy)
        for dy in range(-MAX_OFFSET_PX, MAX_OFFSET_PX + 1)
        for dx in range(-MAX_OFFSET_PX, MAX_OFFSET_PX + 1)
    ]
)
"""(K, 2) every candidate offset (dx, dy); :data:`_UNMOVED` is (0, 0)'s row."""
_UNMOVED = len(_OFFSETS) // 2


@dataclass(frozen=True)
class EdgeContrasts:
    """One or more frames' summed excess-green differences across their depth edges, read at
    each candidate offset (``sums`` (K,), ``counts`` (K,): the pairs with colour on both
    sides there), for :func:`colour_offset`."""

    sums: NDArray[np.float64]
    counts: NDArray[np.int64]

    def __add__(self, other: EdgeContrasts) -> EdgeContrasts:
        return EdgeContrasts(self.sums + other.sums, self.counts + other.counts)


@dataclass(frozen=True)
class ColourOffset:
    """Where a station's colour lies on its depth: ``dx_px`` right and ``dy_px`` down (the
    colour of depth pixel (x, y) is the image's at (x + dx, y + dy)), the mean contrast
    across its depth edges there and where registered (``contrast``, ``registered``), and the
    pairs scored."""

    dx_px: int
    dy_px: int
    contrast: float
    registered: float
    pairs: int

    @property
    def moved(self) -> bool:
        return (self.dx_px, self.dy_px) != (0, 0)

    @property
    def at_search_border(self) -> bool:
        return max(abs(self.dx_px), abs(self.dy_px)) == MAX_OFFSET_PX

    def describe(self) -> str:
        """E.g. ``2 px right, 1 px down``."""
        parts = [
            f"{abs(n)} px {word[n > 0]}"
            for n, word in ((self.dx_px, ("left", "right")), (self.dy_px, ("up", "down")))
            if n
        ]
        return ", ".join(parts) or "in place"


@cache
def _exg_or_nan() -> NDArray[np.float32]:
    """(EXG_KEYS + 1,) float32: each colour key's excess green, NaN for no colour and
    :data:`~fieldapp.recon.exg.NO_KEY` (read-only)."""
    table = np.append(exg_of_keys(), np.nan).astype(np.float32)
    table[uncoloured_keys()] = np.nan
    table[NO_KEY] = np.nan
    table.flags.writeable = False
    return table


def edge_contrasts(
    keys: NDArray[np.int32],
    depth_m: NDArray[np.float32],
    edge_share: float,
    pairs_per_frame: int = PAIRS_PER_FRAME,
) -> EdgeContrasts:
    """A frame's :class:`EdgeContrasts`. ``keys``: (H * W,) its pixels' colour keys
    (:func:`~fieldapp.recon.exg.exg_keys`, ``NO_KEY`` where no depth is measured);
    ``depth_m`` (H, W), NaN unmeasured; a depth edge joins two neighbouring pixels (side by
    side or one above the other) whose depths differ by more than ``edge_share`` of the
    nearer's. Edges within :data:`MAX_OFFSET_PX` of the border are left out, so every offset
    reads the same pairs."""
    height, width = depth_m.shape
    flat = depth_m.reshape(-1)
    margin = MAX_OFFSET_PX
    firsts, steps = [], []
    for step, last_row, last_column in ((1, height, width - 1), (width, height - 1, width)):
        near, far = np.fmin(flat[:-step], flat[step:]), np.fmax(flat[:-step], flat[step:])
        edge = np.flatnonzero(far - near > edge_share * near)  # NaN: no edge
        rows, columns = np.divmod(edge, width)
        inside = (
            (rows >= margin)
            & (rows < last_row - margin)
            & (columns >= margin)
            & (columns < last_column - margin)
        )
        firsts.append(edge[inside])
        steps.append(np.full(int(inside.sum()), step))
    first, step = np.concatenate(firsts), np.concatenate(steps)
    if len(first) > pairs_per_frame:
        chosen = np.linspace(0, len(first) - 1, pairs_per_frame).astype(np.intp)
        first, step = first[chosen], step[chosen]
    table = _exg_or_nan()
    moved = first[None, :] + (_OFFSETS[:, 1] * width + _OFFSETS[:, 0])[:, None]  # (K, n)
    difference = np.abs(table[keys[moved]] - table[keys[moved + step[None, :]]])
    scored = np.isfinite(difference)
    sums = np.where(scored, difference, 0.0).sum(axis=1, dtype=np.float64)
    return EdgeContrasts(sums, scored.sum(axis=1))


def colour_offset(contrasts: EdgeContrasts, uncoloured_share: float) -> ColourOffset | None:
    """The offset (:class:`ColourOffset`) at which a station's colour best agrees with its
    depth edges (``contrasts``, summed over its frames); (0, 0) unless its contrast there is
    at least :data:`MIN_PEAK_RATIO` times the registered one's (:data:`MIN_PEAK_RATIO_WITH_HOLES`
    where more than :data:`HOLES_SHARE` of the station's measured pixels have no colour,
    ``uncoloured_share``); ``None`` where fewer than :data:`MIN_PAIRS` pairs tell."""
    pairs = int(contrasts.counts[_UNMOVED])
    if pairs < MIN_PAIRS or contrasts.counts.min() == 0:
        return None
    means = contrasts.sums / contrasts.counts
    best = int(np.argmax(means))
    registered = float(means[_UNMOVED])
    holes = uncoloured_share > HOLES_SHARE
    if means[best] < (MIN_PEAK_RATIO_WITH_HOLES if holes else MIN_PEAK_RATIO) * registered:
        best = _UNMOVED
    dx, dy = (int(n) for n in _OFFSETS[best])
    return ColourOffset(dx, dy, float(means[best]), registered, pairs)


def moved_colour(color: NDArray[np.uint8], offset: ColourOffset) -> NDArray[np.uint8]:
    """(H, W, 3) ``color`` moved onto its depth: each pixel takes the colour ``offset`` away
    (``color[y + dy, x + dx]``); the rows and columns uncovered at the border are black, the
    session format's "no colour"."""
    dx, dy = offset.dx_px, offset.dy_px
    height, width = color.shape[:2]
    moved = np.zeros_like(color)
    moved[max(-dy, 0) : height - max(dy, 0), max(-dx, 0) : width - max(dx, 0)] = color[
        max(dy, 0) : height + min(dy, 0), max(dx, 0) : width + min(dx, 0)
    ]
    return moved
