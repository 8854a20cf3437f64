"""The backends: the ``Backend`` protocol, what every backend shares (no physics) and the
registry lookup (:mod:`.base`), a run's BLAS threads and FFT workers (:mod:`.threads`),
and the finite-element backend (:mod:`.fem`). The spectral reference stands apart in the
top-level ``spectral_ref`` package.
"""
