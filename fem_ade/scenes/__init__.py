"""What a run starts from: the scene catalogue and TOML scenes (:mod:`.catalogue`), the
initial shapes (:mod:`.initial`), the paper's shapes sized by their diffuse V and A
(:mod:`.seeds`; :mod:`fem_ade.campaigns.seed_sizes` finds the sizes), the ``vesicle`` family
(:mod:`.vesicle`) and its pear where ``sharp_ref`` must continue it (:mod:`.pear`).
"""
