"""The Qt (PySide6) user interface: the top layer, over :mod:`fieldapp` and :mod:`devices`."""
