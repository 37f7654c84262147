"""The application layer: the command line (:mod:`.cli`, with its commands in :mod:`.commands` and
:mod:`.analysis_commands`, output files in :mod:`.outputs`) and the whole tasks on model files it
runs (:mod:`.workflows`).  It holds no logic of its own beyond reading arguments and writing results."""
