"""Pictures: a run's shape.png and history.png (:mod:`.render`, also ``python -m
fem_ade.render``) and a sweep's phase diagram (:mod:`.sweep_plot`).
"""
