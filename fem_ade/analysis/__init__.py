"""What an end state is: the φ = 0 surface's descriptors, labels and verdicts (:mod:`.shape`),
the same from an axisymmetric run's meridians (:mod:`.axishape`), and a run beside
``sharp_ref``'s membrane (:mod:`.sharp`).
"""
