"""Device drivers and simulators: the bottom layer.

Nothing here imports :mod:`fieldapp` or :mod:`ui`, nor any Qt package. A device is a protocol
module (bytes in, bytes out, no I/O), a driver given its transport, and a simulator that serves
the same bytes over the same kind of transport.
"""
