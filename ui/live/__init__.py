"""The live preview: depth, colour and IR images, the 3D cloud of the current frame, the
stream's rates and the capture-quality figures (:mod:`ui.live.preview`)."""
