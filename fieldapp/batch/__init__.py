"""Batch reconstruction of many sessions on Dask (``fieldapp batch``; see ``docs/BATCH.md``).

- :mod:`~fieldapp.batch.plan`: on the client, which sessions to run, skip (already done with
  the same settings hash and software version) or reject (unreadable, duplicate id).
- :mod:`~fieldapp.batch.task`: :func:`~fieldapp.batch.task.reconstruct_session`, the one
  function a worker runs per session (the pipeline unchanged), returning a small summary.
- :mod:`~fieldapp.batch.cluster`: a local cluster (single-threaded worker processes, memory
  limit, quiet logs) or a client of an existing scheduler.
- :mod:`~fieldapp.batch.runner`: submit one task per session, record each run in the results
  database on the client as its future completes, report progress.
"""
