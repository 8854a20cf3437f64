"""What the studies share: a small library beside them, so that no study imports another.

A study is a script, run as ``python studies/NAME.py``; Python puts the script's folder,
``studies/``, first on ``sys.path``, so ``from _lib.MODULE import NAME`` finds this package
with no path handling in the study. The test suite loads each study from its file and finds
``_lib`` the same way: ``pyproject.toml`` puts ``studies/`` on pytest's ``pythonpath``.

Why a package here and not a module of ``fem_ade``: what it holds (the sharp solves' caches,
seeded steady states with the sharp-limit study's rules, the report's extrapolations) is the
studies' method, not the package's; ``fem_ade`` keeps its layers (tests/test_architecture.py)
and knows nothing of ``studies/``. What a study needs that is a scene (the pear's seed) is in
``fem_ade.scenes``.

* :mod:`_lib.cli` — the parser every study starts from, and one thread per process;
* :mod:`_lib.sharp` — sharp membranes solved by ``sharp_ref``, cached on disk, and followed
  along m₀ by continuation;
* :mod:`_lib.fits` — Richardson extrapolation, observed orders, the time to an accuracy;
* :mod:`_lib.seeded` — phase-field steady states seeded from a sharp meridian, run as one
  sweep (the sharp-limit and ADE-plane studies');
* :mod:`_lib.limit_eps`, :mod:`_lib.limit_ade`, :mod:`_lib.limit_transitions` — the stages
  ``eps``, ``ade`` and ``transitions`` of ``studies/sharp_limit.py``, each with its rows and
  its part of the report.
"""
