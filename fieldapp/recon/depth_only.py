"""Reading depth-only captures (no colour image: the spec allows it) for the reconstruction.

The reconstruction's stages carry a colour per point; a depth-only capture gets a neutral grey
(so ``cloud.ply`` is grey there), and the plants are told from the soil by geometry
(:func:`fieldapp.recon.exg.choose_separation`).
"""

from __future__ import annotations

import numpy as np

from fieldapp.errors import FormatError
from fieldapp.io.images import ImageError, read_depth_units
from fieldapp.io.session import Capture, CaptureImages, Session

NEUTRAL_GREY = 128


def read_scan_capture(session: Session, capture: Capture) -> CaptureImages:
    """A capture's images; a depth-only capture's colour is a neutral grey image. Raises
    :class:`FormatError` naming the bad file."""
    if capture.color is not None:
        return session.read_capture(capture)
    camera = session.calibration.depth_camera
    try:
        units = read_depth_units(
            session.path_of(capture.depth), expected=session.expected(capture, "depth")
        )
    except ImageError as error:
        raise FormatError([error.problem]) from None
    grey = np.full((*units.shape, 3), NEUTRAL_GREY, dtype=np.uint8)
    return CaptureImages(capture, camera.metres(units), grey)
