"""Global reconstruction of a maize seedling plot and per-plant traits (the paper's method).

``reconstruct(session, settings)`` in :mod:`fieldapp.recon.pipeline` is the entry point.
"""
