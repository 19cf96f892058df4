"""Studies that answer a question with several seeds and intervals: the hyper-parameter
sweep (:mod:`.sweep`); statistics shared by them in :mod:`.intervals`."""
