"""Pictures: a run's shape.png and history.png (:mod:`.render`, also ``python -m
fem_ade.render``; the shape's views :mod:`.shapes`, the history :mod:`.history`), a sweep's
phase diagram (:mod:`.sweep_plot`), and how every picture is written (:mod:`.figures`).
"""
