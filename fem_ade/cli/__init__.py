"""The command lines: ``python -m fem_ade.run`` (:mod:`.run`) and the ``fem-ade`` console
script (:mod:`.main`), which dispatches to every command.
"""
