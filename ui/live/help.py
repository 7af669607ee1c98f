"""What each figure of the Live page means, in the operator's words (the tooltips)."""

from __future__ import annotations

STREAM_HELP = (
    "camera fps: frames the camera delivered per second; shown fps: frames drawn here.\n"
    "dropped by the camera: frames the camera's driver reported lost before they reached "
    "fieldapp (USB bandwidth or a busy computer); a few are harmless, a steady climb means "
    "the USB 3 link or the computer cannot keep up.\n"
    "replaced before shown: frames that arrived while the screen was still busy with the "
    "previous one, so a newer frame replaced them; normal when the camera (30 fps) is faster "
    "than the screen refresh. Captures never lose frames this way.\n"
    "frames: frames received since Connect."
)
QUALITY_HELP: dict[str, str] = {
    "depth fill rate": "Share of the crop region with a valid depth (holes inside the "
    "region count as missing). Low: direct sun, a dirty lens, or surfaces too close.",
    "crop region": "How much of the image is the crop region: the surfaces the camera sees "
    "within the crop radius (Devices settings), which the reconstruction keeps; the far "
    "field and the sky are not in it. Near 0: the lens is covered or nothing is in range.",
    "flying pixels": "Share of the crop region's pixels that float between the two sides "
    "of a depth edge (mixed distances). High: motion, wind, or the plants too close.",
    "over-exposed": "Share of colour pixels saturated. High: direct sun or shiny surfaces in view.",
    "under-exposed": "Share of colour pixels almost black. High: too dark to see the "
    "plants in colour.",
    "frame age": "Time since the newest frame was taken. High: the camera stalled or the "
    "computer is overloaded.",
}
MEASURE_HELP = (
    "Click a point on the depth (or colour) image, then a second: the straight-line distance "
    "between the two surface points in 3D, in metres, from the camera's depth and its "
    "intrinsics (a click on a pixel without depth takes the nearest measured pixel within 3 "
    "pixels). A third click starts a new pair; a right click clears them. Freeze first to "
    "measure on a still frame. Points are in the camera frame: x right, "
    "y down, z forward."
)
