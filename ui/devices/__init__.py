"""The rig's devices in the GUI: the hub that opens and closes them off the GUI thread
(:mod:`ui.devices.hub`), the connection tests (:mod:`ui.devices.probe`) and the settings
dialog (:mod:`ui.devices.dialog`)."""
