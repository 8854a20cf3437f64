"""What drives a run: one time loop for every backend (:mod:`.loop`), every choice of a run
checked once (:mod:`.config`), ``simulate``/``resume`` and the run folder (:mod:`.runs`),
and ``ensure``, the one way a run's result is made to exist (:mod:`.jobs`).
"""
