"""Scoring: specs in, typed results out (:func:`.run.run_specs`). Reads data, prints and writes
nothing; the Dask path (:mod:`.cluster`) and the diagnosis of failing signals live here too."""
