"""Many runs or states at once: parameter sweeps on Dask (:mod:`.sweep`), branches by
continuation (:mod:`.branch`) and the stability of a steady state (:mod:`.stability`), each
also a command (``python -m fem_ade.sweep|branch|stability``); and the seeds' sizes fitted
by runs (:mod:`.seed_sizes`).
"""
