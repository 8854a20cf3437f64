"""Many runs or states at once: parameter sweeps on Dask (:mod:`.sweep`; a sweep's file
:mod:`.sweep_file`, a point and its row :mod:`.sweep_points`), branches by continuation
(:mod:`.branch`; its numerics :mod:`.continuation`, its folder :mod:`.branch_folder`, what
its rows show :mod:`.branch_analysis`), the stability of a steady state (:mod:`.stability`)
and the switch from a bifurcation into 3D (:mod:`.switch`), each also a command (``python -m
fem_ade.sweep|branch|stability|switch``); and the seeds' sizes fitted by runs
(:mod:`.seed_sizes`).
"""
