"""What a run leaves on disk: history.csv, summary.json, final.npz and checkpoints
(:mod:`.output`), a campaign's table (:mod:`.tables`), ParaView series (:mod:`.xdmf`), one
owner per folder (:mod:`.lock`), signals held while files are written (:mod:`.interrupt`) and
the words for how a run ended (:mod:`.status`).
"""
