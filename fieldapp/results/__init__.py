"""The season's results database: plots, sessions, runs, plants with one id all season, traits,
hand measurements (:class:`fieldapp.results.db.ResultsDB`)."""
