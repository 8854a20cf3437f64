"""The model: its parameters and effects (:mod:`.params`: ``Params``, the scalar parts of
E_M, stabilization) and the exact constraints' multipliers (:mod:`.constraints`). Numbers
in, numbers out; no backend, no scene, no file.
"""
