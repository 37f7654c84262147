"""Views of results: time-history plots (:mod:`.plotting`) and animations (:mod:`.animation`)."""
